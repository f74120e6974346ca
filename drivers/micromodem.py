"""``backend: micromodem``: a real WHOI Micro-Modem behind a link id, on a serial port.

At start (and after every reconnection or ``$CAREV``) the driver sets the modem's address
(``$CCCFG,SRC,<address>``, answered ``$CACFG``).  A GLI frame then goes out as one packet of the
configured ``rate``: its bytes on air cut into the rate's frames (:data:`~.micromodem_codec.RATES`: at
most 3 × 64 bytes at rate 1, 8 × 256 at rate 5), with ``$CCCYC`` and a ``$CCTXD`` for each ``$CADRQ``;
a frame larger than the rate's packet is refused when the application sends it, with the sizes.  The
cycle ends with ``$CATXF`` (then the next frame goes), or fails: ``$CAERR`` (``DATA_TIMEOUT``, a refusal;
the frame is dropped, counted and traced with the modem's words) or no answer within
``cycle_timeout_s``.  With ``ack: true`` each frame asks for the receiving modem's acknowledgement and
the next waits for it (sent at once, it would meet the acknowledgement on the channel): ``$CAACK`` lines
are traced, a frame all of whose frames were acknowledged is traced ``delivered``, one still waiting
after ``ack_timeout_s`` ``failed`` (and dropped, cause ``no_ack``).

Received packets (``$CACYC`` then a ``$CARXD`` per frame) are joined and parsed by the link's packet
class; ``$CACST`` figures go into the trace (``ev: modem_stats``: mode, rate, frames, bad frames, SNR,
data quality factor), and a packet the modem could not decode (bad frames) is counted and traced
(``err``, cause ``bad_crc``).  Micro-Modem address 0 is broadcast (255 for the GLI).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable

from hilgate.core.backend import AppFrame
from hilgate.core.packets import BROADCAST, PacketClass, PacketError, Raw

from .micromodem_codec import RATES, BadSentence, HostCodec, Sentence, sentence
from .modem_backend import ModemBackend
from .table import MICROMODEM_LIMITS, MODES, MicromodemOptions  # declared in the backend table, with its scene checks

log = logging.getLogger(__name__)

MM_BROADCAST = 0


@dataclass
class _Outgoing:
    frame: AppFrame
    pieces: list[bytes]
    dest: int
    ack: bool
    echoed: bool = False
    given: int = 0


@dataclass
class _Incoming:
    src: int
    dest: int
    count: int
    frames: dict[int, bytes] = field(default_factory=dict)


class MicromodemBackend(ModemBackend):
    kind = "micromodem"

    def __init__(self, link_id: str, address: int, packet: PacketClass, options: MicromodemOptions, scheduler: Any,
                 trace: Callable[[dict], Any]):
        super().__init__(link_id, address, packet, options, scheduler, trace)
        self.rate = RATES[options.rate]
        self.codec = HostCodec()
        self.sending: _Outgoing | None = None
        self.incoming: _Incoming | None = None
        self.awaiting: tuple[int, AppFrame, set[int]] | None = None  # (dest, frame, frame numbers to be acknowledged)
        self.timer = None
        self._open_port()

    @property
    def idle(self) -> bool:
        return not self.queue and self.sending is None and self.awaiting is None

    def admit(self, frame: AppFrame) -> None:
        """A frame larger than a packet of the link's rate is refused when the application sends it, in the
        words a simulated link with the same preset uses (``drivers/table.py``, ModemLimits)."""
        limits = self.options.limits or MICROMODEM_LIMITS
        mode = f"rate{self.options.rate}"
        most = min(limits.most(mode) or self.rate.packet_bytes, self.rate.packet_bytes)
        if len(frame.real) > most:
            raise PacketError("size", limits.refusal(len(frame.real), mode)
                              or f"{len(frame.real)} bytes on air do not fit {MODES[mode]} of the Micro-Modem "
                                 f"(at most {most})")

    def send(self, frame: AppFrame) -> bool:
        self.admit(frame)
        return super().send(frame)

    def close(self) -> None:
        self.scheduler.cancel(self.timer)
        super().close()

    # -- the port and the start-up ---------------------------------------------------------------------

    def _on_port(self, up: bool, reason: str | None) -> None:
        self.codec = HostCodec()
        self.incoming = None
        self._requeue()
        if up:
            self._start()
        else:
            self.set_state("down", reason)

    def _requeue(self) -> None:
        self.scheduler.cancel(self.timer)
        self.timer = None
        self.awaiting = None  # its acknowledgement, if it comes, is traced but frees nothing
        if self.sending is not None:  # the cycle died with the port or the modem: the frame goes again
            self.queue.appendleft(self.sending.frame)
            self.sending = None

    def _start(self) -> None:
        self.set_state("starting")
        self.port.write(sentence("CCCFG", "SRC", self.address))
        self.timer = self.scheduler.after_wall(self.options.command_timeout_s, self._no_answer)

    def _no_answer(self) -> None:
        self.timer = None
        log.warning("%s: no $CACFG,SRC from the modem; asking again", self.link_id)
        self.set_state("starting", "no answer to $CCCFG,SRC")
        if self.port.up:
            self._start()

    # -- frames out: one cycle at a time -----------------------------------------------------------------

    def pump(self) -> None:
        if self._state != "up" or self.sending is not None or self.awaiting is not None or not self.queue:
            return
        frame = self.queue.popleft()
        real = frame.real if not isinstance(self.packet, Raw) else frame.payload
        size = self.rate.frame_bytes
        pieces = [real[i:i + size] for i in range(0, len(real), size)] or [b""]
        dest = MM_BROADCAST if frame.dst == BROADCAST else frame.dst
        self.sending = _Outgoing(frame, pieces, dest, self.options.ack and dest != MM_BROADCAST)
        self.port.write(sentence("CCCYC", 0, self.address, dest, self.options.rate, int(self.sending.ack), len(pieces)))
        self.timer = self.scheduler.after_wall(self.options.cycle_timeout_s, self._cycle_timeout)

    def _cycle_timeout(self) -> None:
        self.timer = None
        if self.sending is not None:
            self._failed("no_report", "no $CATXF within cycle_timeout_s")

    def _failed(self, cause: str, why: str) -> None:
        outgoing = self.sending
        self.sending = None
        self.scheduler.cancel(self.timer)
        self.timer = None
        if outgoing is not None:
            log.warning("%s: a frame was not sent: %s", self.link_id, why)
            self.drop(outgoing.frame, cause)
        self._next()

    def _next(self) -> None:
        if self.idle and self.on_idle is not None:
            self.on_idle()
        self.pump()

    # -- bytes in --------------------------------------------------------------------------------------------

    def _on_data(self, data: bytes) -> None:
        for event in self.codec.receive_data(data):
            if isinstance(event, BadSentence):
                log.info("%s: noise from the modem (%s): %r", self.link_id, event.reason, event.data[:40])
                continue
            handler = self.HANDLERS.get(event.kind)
            if handler is not None:
                handler(self, event)

    def _config(self, s: Sentence) -> None:
        if s.field(0) == "SRC" and self._state != "up":
            if s.number(1) != self.address:
                log.warning("%s: the modem says SRC %s, not %d", self.link_id, s.field(1), self.address)
            self.scheduler.cancel(self.timer)
            self.timer = None
            self.set_state("up")
            self.pump()

    def _cycle(self, s: Sentence) -> None:
        src, dest, count = s.number(1), s.number(2), s.number(5)
        if src is None or dest is None or count is None:
            return
        outgoing = self.sending
        if outgoing is not None and not outgoing.echoed and src == self.address:
            outgoing.echoed = True  # the echo of our $CCCYC
            return
        if src != self.address:  # a packet from another modem is arriving
            most = max(rate.frames for rate in RATES.values())  # a modem's claim of more frames is bounded
            self.incoming = _Incoming(src, dest, max(1, min(count, most)))

    def _request(self, s: Sentence) -> None:
        outgoing = self.sending
        number = s.number(5)
        if outgoing is None or number is None or not 1 <= number <= len(outgoing.pieces):
            return
        outgoing.given = number
        self.port.write(sentence("CCTXD", self.address, outgoing.dest, int(outgoing.ack),
                                 outgoing.pieces[number - 1].hex().upper()))

    def _transmitted(self, s: Sentence) -> None:
        outgoing = self.sending
        if outgoing is None or outgoing.given < len(outgoing.pieces) or s.number(0) == 0:
            return  # a rate-0 cycle init went out, or an acknowledgement of ours: not our packet
        self.sending = None
        self.scheduler.cancel(self.timer)
        self.timer = None
        frame = outgoing.frame
        self.tx_packets += 1
        self.event("tx", dst=frame.dst, size=len(frame.real), rate=self.options.rate, frames=len(outgoing.pieces))
        if outgoing.ack:
            # the next packet waits for the acknowledgement: sent now, it would meet it on the channel
            self.awaiting = (outgoing.dest, frame, set(range(1, len(outgoing.pieces) + 1)))
            self.timer = self.scheduler.after_wall(self.options.ack_timeout_s, self._ack_timeout)
            return
        self._next()

    def _ack_timeout(self) -> None:
        self.timer = None
        if self.awaiting is not None:
            _, frame, numbers = self.awaiting
            self.awaiting = None
            self.event("failed", dst=frame.dst, frames=sorted(numbers))
            self.drop(frame, "no_ack")
            self._next()

    def _error(self, s: Sentence) -> None:
        text = ",".join(s.fields[1:])
        self.event("modem_error", cause=text)
        if self.sending is not None:
            timeout = s.field(1) == "DATA_TIMEOUT"
            if timeout and self.sending.given > 1:
                return  # the frames given so far still go: $CATXF ends the cycle
            self._failed("data_timeout" if timeout else "refused", text)

    def _acknowledged(self, s: Sentence) -> None:
        dest, number = s.number(1), s.number(2)
        self.event("ack", src=dest, frame=number)
        if self.awaiting is None or self.awaiting[0] != dest:
            return
        _, frame, numbers = self.awaiting
        numbers.discard(number)
        if not numbers:
            self.awaiting = None
            self.scheduler.cancel(self.timer)
            self.timer = None
            self.event("delivered", dst=frame.dst)
            self._next()

    def _received(self, s: Sentence) -> None:
        incoming = self.incoming
        number = s.number(3)
        if incoming is None or number is None or s.number(0) != incoming.src:
            return
        try:
            incoming.frames[number] = bytes.fromhex(s.field(4) or "")
        except ValueError:
            return
        if len(incoming.frames) >= incoming.count:
            self.incoming = None
            self._packet(incoming)

    def _packet(self, incoming: _Incoming) -> None:
        data = b"".join(incoming.frames[k] for k in sorted(incoming.frames))
        src = incoming.src
        dst = BROADCAST if incoming.dest == MM_BROADCAST else incoming.dest
        try:
            if isinstance(self.packet, Raw):
                real, payload = data, data
            else:
                real, payload, _, _ = self.packet.parse_real(data)
        except PacketError as exc:
            self.drops += 1
            self.event("err", src=src, size=len(data), cause=exc.reason)
            return
        self.rx_packets += 1
        self.event("rx", src=src, dst=dst, size=len(real))
        if self.on_receive is not None:
            self.on_receive(AppFrame(real, payload, self.packet, 0, src, dst, self.scheduler.now()))

    def _statistics(self, s: Sentence) -> None:
        fields = s.fields
        if len(fields) < 30 or s.number(0) is None or s.number(0) < 6:
            return  # only the Micro-Modem 2's statistics (version 6 and later) are read
        mode, rate, src, dest = s.number(1), s.number(13), s.number(14), s.number(15)
        frames, bad = s.number(18), s.number(19)
        self.event("modem_stats", mode=mode, rate=rate, src=src, dst=dest, frames=frames, bad_frames=bad,
                   snr_in=fields[21], dqf=s.number(25), doppler=fields[26])
        if mode == 1 and dest in (self.address, MM_BROADCAST):
            self.incoming = None
            self.drops += 1
            self.event("err", src=src, frames=frames, cause="bad_crc")

    def _restarted(self, s: Sentence) -> None:
        log.warning("%s: the modem restarted ($CAREV)", self.link_id)
        self.incoming = None
        self._requeue()
        self._start()

    HANDLERS = {"CACFG": _config, "CACYC": _cycle, "CADRQ": _request, "CATXF": _transmitted, "CAERR": _error,
                "CAACK": _acknowledged, "CARXD": _received, "CACST": _statistics, "CAREV": _restarted}
