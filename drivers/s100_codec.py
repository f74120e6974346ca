"""WFS Seatooth S100 framing, without I/O: the bytes dccomms' S100 bridge writes, and a frame hunter.

The S100 is a transparent byte pipe with no command set (``shared/protocols/s100-mavlink-aruco.md``):
a packet is the link's packet bytes followed by CR LF.  Without RTS/CTS flow control the modem takes
at most 45 bytes at a time, so the bridge writes 45-byte pieces paced at the air bitrate, then the
CR LF.  The receiver hunts frames in the byte stream by the packet class's preamble, length and CRC,
skipping stray CR LF and ``+++…\\r\\n`` modem notices.  ``raw`` links, which have no framing of their
own, get :class:`hilgate.core.packets.HilgateFrame`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hilgate.core.packets import BROADCAST, Decoded, HilgateFrame, PacketClass, PacketError, Raw

CRLF = b"\r\n"
PIECE = 45
MAX_NOTICE = 200


def wire_class(packet: PacketClass) -> PacketClass:
    """The framing used on the serial line for a link's packet class."""
    return HilgateFrame() if isinstance(packet, Raw) else packet


def pieces(real: bytes, rtscts: bool) -> list[bytes]:
    """What to write, in order: the whole packet then CR LF with RTS/CTS; else 45-byte pieces, the
    last one followed by CR LF (each piece is to be paced at the air bitrate)."""
    if rtscts:
        return [real + CRLF]
    chunks = [real[i : i + PIECE] for i in range(0, len(real), PIECE)] or [b""]
    chunks.append(CRLF)
    return chunks


@dataclass(frozen=True)
class Notice:
    """A ``+++…`` line from the modem itself (content undocumented): skipped, logged."""

    text: bytes


@dataclass(frozen=True)
class Skipped:
    """Bytes that were no frame (line noise, a frame with a bad CRC…), with why."""

    count: int
    reason: str


@dataclass
class FrameHunter:
    packet: PacketClass
    _buffer: bytearray = field(default_factory=bytearray)

    def __post_init__(self) -> None:
        self.packet = wire_class(self.packet)

    def receive_data(self, data: bytes) -> list[object]:
        self._buffer += data
        events: list[object] = []
        while True:
            event = self._next()
            if event is None:
                break
            events.append(event)
        return events

    def _frame_at(self, position: int) -> str:
        """``frame`` if a whole valid frame starts at ``position``, ``more`` if it may once more bytes
        arrive, ``no`` otherwise."""
        buffer = self._buffer
        try:
            total = self.packet.frame_length(bytes(buffer[position:position + 8]))
        except PacketError:
            return "no"
        if total is None or len(buffer) < position + total:
            return "more"
        try:
            self.packet.parse_real(bytes(buffer[position:position + total]))
        except PacketError:
            return "no"
        return "frame"

    def _skip(self, count: int, reason: str) -> Skipped:
        del self._buffer[:count]
        return Skipped(count, reason)

    def _next(self) -> object | None:
        buffer = self._buffer
        packet = self.packet
        preamble = packet.preamble
        while buffer[:1] in (b"\r", b"\n"):
            del buffer[:1]
        if not buffer:
            return None
        if buffer[:3] == b"+++":
            end = buffer.find(CRLF, 0, MAX_NOTICE)
            limit = end if end >= 0 else min(len(buffer), MAX_NOTICE)
            # a notice ends at its CR LF, or where a whole valid frame starts inside it (line noise
            # that merely begins with "+++" must not swallow the frame behind it)
            position = buffer.find(preamble, 3, limit)
            arriving = False
            while position >= 0:
                found = self._frame_at(position)
                if found == "frame":
                    text = bytes(buffer[:position])
                    del buffer[:position]
                    return Notice(text)
                arriving = arriving or found == "more"
                position = buffer.find(preamble, position + 1, limit)
            if end >= 0 and arriving and self._frame_at(end + 2) != "frame":
                # a frame that starts before the CR LF is still arriving and nothing proves the CR LF
                # ends the notice: it may be inside that frame's payload, so wait (one frame at most)
                return None
            if end >= 0:
                text = bytes(buffer[:end])
                del buffer[: end + 2]
                return Notice(text)
            if len(buffer) < MAX_NOTICE:
                return None
            return self._skip(3, "notice without end")
        start = buffer.find(preamble)
        if start < 0:
            keep = len(preamble) - 1 if buffer.endswith(preamble[:1]) else 0
            if len(buffer) > keep:
                return self._skip(len(buffer) - keep, "no preamble")
            return None
        if start > 0:
            # a notice may begin inside the junk: stop there to give it its own chance
            notice = buffer.find(b"+++", 0, start)
            return self._skip(notice if notice > 0 else start, "no preamble")
        try:
            total = packet.frame_length(bytes(buffer[:8]))
        except PacketError as exc:
            return self._skip(1, exc.reason)
        if total is None or len(buffer) < total:
            # waiting for a long frame; but if a whole valid frame already follows, this preamble was a
            # stray byte whose "length" would hold good frames back for nothing
            position = buffer.find(preamble, 1)
            while position >= 0:
                if self._frame_at(position) == "frame":
                    return self._skip(position, "false preamble")
                position = buffer.find(preamble, position + 1)
            return None
        try:
            real, payload, src, dst = packet.parse_real(bytes(buffer[:total]))
        except PacketError as exc:
            return self._skip(1, exc.reason)
        del buffer[:total]
        return Decoded(real, payload, 0, BROADCAST if src is None else src, BROADCAST if dst is None else dst)
