"""WFS Seatooth S100 framing, without I/O: the bytes dccomms' S100 bridge writes, and a frame hunter.

The S100 is a transparent byte pipe with no command set (``shared/protocols/s100-mavlink-aruco.md``):
a packet is the link's packet bytes followed by CR LF.  Without RTS/CTS flow control the modem takes
at most 45 bytes at a time, so the bridge writes 45-byte pieces paced at the air bitrate, then the
CR LF (hilgate's driver puts the CR LF in the last piece: see :func:`pieces`).  The receiver hunts frames in the byte stream by the packet class's preamble, length and CRC,
skipping stray CR LF and ``+++…\\r\\n`` modem notices.  ``raw`` links, which have no framing of their
own, get :class:`hilgate.core.packets.HilgateFrame`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hilgate.core.packets import BROADCAST, Decoded, HilgateFrame, PacketClass, PacketError, Raw

CRLF = b"\r\n"
PIECE = 45  # without flow control (the link's limits: piece_bytes; drivers/table.py S100_LIMITS)
MAX_NOTICE = 200
EPS = 1e-9
LINE_BITS = 10  # 8N1: a start bit, 8 data bits and a stop bit on the serial line for each byte
TERMINATOR = "terminator"  # the reason of a Skipped that is only CR and LF between frames
IDLE_S = 0.1
"""How long the emulated S100 holds bytes that are no frame (yet) before it sends them as they are.
The real modem sends a packet under 45 bytes "after a timeout" unless CR LF arrives; its value is
not documented, this one is hilgate's choice."""


def byte_time(baud: int) -> float:
    """Seconds one byte takes on a serial line at ``baud`` (8N1): 10 / baud, ~0.52 ms at 19 200."""
    return LINE_BITS / baud


class SerialLine:
    """One direction of a serial line, without I/O: when each byte written has crossed it.

    A pty carries bytes at once; a real line at ``baud`` one byte every :func:`byte_time`, one write
    after the other.  :meth:`send` says when the last byte of a write made at ``t`` arrives."""

    def __init__(self, baud: int, speed: float = 1.0):
        self.byte_time = byte_time(baud) * speed  # in the clock's seconds (a clock may run ``speed`` times faster)
        self.free_at = float("-inf")

    def send(self, t: float, size: int) -> float:
        """The write of ``size`` bytes at ``t`` starts when the line is free; the time its last byte is in."""
        start = max(t, self.free_at)
        self.free_at = start + size * self.byte_time
        return self.free_at


class InputBuffer:
    """The S100's 45 bytes without flow control, without I/O: the modem sends what it holds at the
    air bitrate (``drain_Bps``), and a byte that arrives when the buffer is full is lost (nothing tells
    the host to wait).  A writer that paces itself at the air bitrate, as dccomms' bridge and hilgate's
    driver do, loses nothing; one that writes a long frame at once loses its tail."""

    def __init__(self, drain_Bps: float, capacity: int = PIECE):
        self.drain_Bps = drain_Bps
        self.capacity = capacity
        self.level = 0.0
        self.t = float("-inf")

    def accept(self, t: float, size: int, byte_time: float) -> list[bool]:
        """Bytes arriving one every ``byte_time`` from ``t`` (the first at ``t + byte_time``): whether
        each one fits (:meth:`fit` with every byte's arrival known)."""
        return self.fit(t, [t + i * byte_time for i in range(1, size + 1)], byte_time)[0]

    def fit(self, earliest: float, latest: list[float], byte_time: float) -> tuple[list[bool], float]:
        """Bytes that came one after another, no closer than ``byte_time``, the first no earlier than
        ``earliest + byte_time`` and byte ``i`` no later than ``latest[i]``, when exactly is unknown: each is
        taken to come at the earliest moment it fits.  That is the arrival most favourable to it and to every
        byte after it (an earlier byte leaves the buffer emptier later, and its followers more room), so a
        byte is lost only where no arrival within the bounds keeps it.  Whether each fits, and when the last
        one is taken to have come (lost bytes took the line's time too, at their earliest)."""
        kept = []
        t = earliest
        for last in latest:
            t += byte_time
            if t > self.t:
                self.level = max(0.0, self.level - (t - self.t) * self.drain_Bps)
                self.t = t
            if self.level + 1 > self.capacity + EPS and self.drain_Bps > 0:
                room = self.t + (self.level + 1 - self.capacity) / self.drain_Bps  # when one byte's room is free
                if room <= last + EPS:
                    self.level, self.t, t = self.capacity - 1.0, room, room
            fits = self.level + 1 <= self.capacity + EPS
            if fits:
                self.level += 1
            kept.append(fits)
        return kept, t



def wire_class(packet: PacketClass) -> PacketClass:
    """The framing used on the serial line for a link's packet class."""
    return HilgateFrame() if isinstance(packet, Raw) else packet


def pieces(real: bytes, rtscts: bool, piece: int = PIECE) -> list[bytes]:
    """What to write, in order: the whole packet then CR LF with RTS/CTS; else the packet and its CR LF
    cut into 45-byte pieces (each to be paced at the air bitrate).

    The CR LF rides in the last piece rather than alone after it: a modem holding a piece shorter than
    45 bytes sends it when its CR LF comes *or when its timeout runs out*, and a CR LF written one pacing
    sleep later (``len * 8 / bitrate``, 80 ms for 10 bytes at 1 kbit/s) lands after that timeout on a
    busy host, so the frame's tail would go on air as a packet of its own and the CR LF as another.
    Every piece but the last is full (the modem sends it at once); the last ends with the terminator."""
    if rtscts:
        return [real + CRLF]
    wire = real + CRLF
    return [wire[i : i + piece] for i in range(0, len(wire), piece)]


@dataclass(frozen=True)
class Notice:
    """A ``+++…`` line from the modem itself (content undocumented): skipped, logged.  ``ended``: it ended
    at its CR LF (taken with it), not where a frame starts."""

    text: bytes
    ended: bool = True

    @property
    def data(self) -> bytes:
        """The bytes it took from the stream (a transparent pipe passes them on as they were)."""
        return self.text + CRLF if self.ended else self.text


@dataclass(frozen=True)
class Skipped:
    """Bytes that were no frame (line noise, a frame with a bad CRC…), with why, and the bytes."""

    count: int
    reason: str
    data: bytes = b""


@dataclass
class FrameHunter:
    packet: PacketClass
    _buffer: bytearray = field(default_factory=bytearray)

    consumed: int = 0  # bytes taken out of the stream so far (events end there)

    def __post_init__(self) -> None:
        self.packet = wire_class(self.packet)

    def receive_data(self, data: bytes) -> list[object]:
        return [event for event, _ in self.receive_data_at(data)]

    def receive_data_at(self, data: bytes) -> list[tuple[object, int]]:
        """As :meth:`receive_data`, each event with the stream offset where it ends (after the bytes
        it took, leading CR/LF included): an emulator times each frame by its own last byte."""
        self._buffer += data
        events: list[tuple[object, int]] = []
        fed = self.consumed + len(self._buffer)
        while True:
            event = self._next()
            if event is None:
                break
            events.append((event, fed - len(self._buffer)))
        self.consumed = fed - len(self._buffer)
        return events

    @property
    def fed(self) -> int:
        """Bytes given to the hunter so far: the stream offset where the next data will start."""
        return self.consumed + len(self._buffer)

    @property
    def held(self) -> int:
        """Bytes the hunter holds (the start of a frame still arriving, a notice without its end…)."""
        return len(self._buffer)

    def take(self, count: int) -> bytes:
        """Take the first ``count`` held bytes out of the stream (an emulated S100 sends them on)."""
        data = bytes(self._buffer[:count])
        del self._buffer[:count]
        self.consumed += len(data)
        return data

    def flush(self) -> bytes:
        """Give up on what is held (a frame that will not complete, a notice without end): the bytes."""
        rest = bytes(self._buffer)
        self.consumed += len(rest)
        self._buffer.clear()
        return rest

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

    def _frame_after(self, start: int) -> bool:
        """Whether a whole valid frame starts at or after ``start``."""
        position = self._buffer.find(self.packet.preamble, start)
        while position >= 0:
            if self._frame_at(position) == "frame":
                return True
            position = self._buffer.find(self.packet.preamble, position + 1)
        return False

    def _skip(self, count: int, reason: str) -> Skipped:
        data = bytes(self._buffer[:count])
        del self._buffer[:count]
        return Skipped(count, reason, data)

    def _notice(self) -> object | None:
        """A ``+++`` notice at the buffer's start: up to its CR LF, or up to a whole valid frame inside it;
        None to wait for more."""
        buffer = self._buffer
        preamble = self.packet.preamble
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
                return Notice(text, ended=False)
            arriving = arriving or found == "more"
            position = buffer.find(preamble, position + 1, limit)
        if end >= 0 and arriving and not self._frame_after(end + 2):
            # a frame that starts before the CR LF is still arriving and nothing proves the CR LF
            # ends the notice: it may be inside that frame's payload, so wait (one frame at most).
            # A whole valid frame after the CR LF is such a proof, even behind other junk: a "U"
            # in "EFAULT" must not hold good frames back until its would-be length has come
            return None
        if end >= 0:
            text = bytes(buffer[:end])
            del buffer[: end + 2]
            return Notice(text)
        if len(buffer) < MAX_NOTICE:
            return None
        return self._skip(3, "notice without end")

    def _next(self) -> object | None:
        buffer = self._buffer
        packet = self.packet
        preamble = packet.preamble
        ends = 0
        while buffer[ends:ends + 1] in (b"\r", b"\n"):
            ends += 1
        if ends:
            return self._skip(ends, TERMINATOR)  # a packet's CR LF (an emulated pipe passes them on)
        if not buffer:
            return None
        if buffer[:3] == b"+++":
            return self._notice()
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
