"""What the receiving side of a real modem does with an emulated modem's bytes, without I/O.

An emulated modem's host writes bytes, not GLI frames: an EvoLogics host puts a message's payload in
``AT*SENDIM``/``AT*SEND``, an S100 host writes its frames and CR LF, which a modem without flow control
puts on air in 45-byte pieces.  On a real bench a modem and its dccomms bridge (or hilgate's driver)
receive those bytes and hand the applications the frames of their packet class: an EvoLogics message
is parsed as one frame, an S100's byte stream is hunted for frames across pieces.  A simulated link
does the same with :class:`ReceivingBridge` before its applications get what an emulated modem sent,
so a 100-byte frame that crossed as 45/45/12-byte pieces reaches a dccomms application whole, and
bytes that make no frame are counted and traced as the bridge would drop them.  A Modem-M64's 8-byte
packets are joined into WlUDPSocket datagrams as hilgate's M64 driver joins them (its sync packets are
none), a Micro-Modem packet's frames are one frame, as its driver parses them (its pings and cycle-init
minipackets carry none).

Frames from GLI applications and flows are frames already; only an emulator's bytes (``meta`` set,
packet class ``raw``) come here.  A ``raw`` link takes an EvoLogics message as it is, as the driver does.
"""

from __future__ import annotations

from dataclasses import dataclass

from hilgate.core.backend import AppFrame
from hilgate.core.packets import BROADCAST, Decoded, PacketClass, PacketError, Raw

from .m64_codec import BadDatagram, Datagram, Deframer
from .s100_codec import TERMINATOR, FrameHunter, Notice, Skipped

__all__ = ["ReceivingBridge", "Loss", "from_emulator"]

MAX_SENDERS = 1024  # hunters kept at once (one per sending address; a channel holds at most 255 of them)


@dataclass(frozen=True)
class Loss:
    """Bytes that made no frame: how many, and why (the hunter's reason, or the packet class's)."""

    size: int
    reason: str


def from_emulator(frame: AppFrame) -> bool:
    """Whether ``frame`` is an emulated modem's bytes rather than a frame (the one test on the hot path)."""
    return frame.meta is not None and isinstance(frame.packet, Raw)


class ReceivingBridge:
    """One receiving link's bridge: an S100 hunter per sender, the packet class to parse with."""

    def __init__(self, packet: PacketClass):
        self.packet = packet
        self.hunters: dict[int, FrameHunter] = {}
        self.deframers: dict[int, Deframer] = {}

    def take(self, frame: AppFrame) -> tuple[list[AppFrame], list[Loss]]:
        """The frames of the link's class in what an emulated modem sent, and what made none."""
        meta = frame.meta or {}
        if meta.get("s100") == "raw":
            return self._pieces(frame)
        if "m64" in meta:
            return self._m64_packet(frame) if meta["m64"] == "data" else ([], [])
        if meta.get("mm") in ("ping", "ci"):
            return [], []
        if isinstance(self.packet, Raw):
            return [frame], []
        try:
            real, payload, src, dst = self.packet.parse_real(frame.payload)
        except PacketError as exc:
            return [], [Loss(len(frame.payload), exc.reason)]
        return [self._frame(frame, real, payload, src, dst)], []

    def _pieces(self, frame: AppFrame) -> tuple[list[AppFrame], list[Loss]]:
        hunter = self.hunters.get(frame.src)
        if hunter is None:
            if len(self.hunters) >= MAX_SENDERS:
                self.hunters.pop(next(iter(self.hunters)))
            hunter = self.hunters[frame.src] = FrameHunter(self.packet)
        frames, losses = [], []
        for event in hunter.receive_data(frame.payload):
            if isinstance(event, Decoded):
                real = event.payload if isinstance(self.packet, Raw) else event.real
                frames.append(self._frame(frame, real, event.payload,
                                          None if event.src == BROADCAST else event.src,
                                          None if event.dst == BROADCAST else event.dst))
            elif isinstance(event, Skipped) and event.reason != TERMINATOR:
                losses.append(Loss(event.count, event.reason))
            elif isinstance(event, Notice):
                losses.append(Loss(len(event.text) + 2, "notice"))
        return frames, losses

    def _m64_packet(self, frame: AppFrame) -> tuple[list[AppFrame], list[Loss]]:
        deframer = self.deframers.get(frame.src)
        if deframer is None:
            if len(self.deframers) >= MAX_SENDERS:
                self.deframers.pop(next(iter(self.deframers)))
            deframer = self.deframers[frame.src] = Deframer()
        frames, losses = [], []
        for event in deframer.receive_packet(frame.payload):
            if isinstance(event, BadDatagram):
                losses.append(Loss(event.size, event.reason))
            elif isinstance(event, Datagram):
                if isinstance(self.packet, Raw):
                    frames.append(self._frame(frame, event.data, event.data, None, None))
                    continue
                try:
                    real, payload, src, dst = self.packet.parse_real(event.data)
                except PacketError as exc:
                    losses.append(Loss(len(event.data), exc.reason))
                    continue
                frames.append(self._frame(frame, real, payload, src, dst))
        return frames, losses

    def _frame(self, frame: AppFrame, real: bytes, payload: bytes, src: int | None, dst: int | None) -> AppFrame:
        """A frame of the link's class, from the sender the channel says (a class with addresses on air
        says its own)."""
        return AppFrame(real, payload, self.packet, 0, frame.src if src is None else src,
                        frame.dst if dst is None else dst, frame.t0)

    def flush(self) -> list[Loss]:
        """What the hunters hold that will never be a frame now (the link closes or changes class)."""
        losses = [Loss(hunter.held, "incomplete") for hunter in self.hunters.values() if hunter.held]
        losses += [Loss(len(d.buffer), "incomplete") for d in self.deframers.values() if d.buffer]
        self.hunters.clear()
        self.deframers.clear()
        return losses
