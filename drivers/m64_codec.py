"""Water Linked Modem-M64 serial protocol and its datagram framing, without I/O.

The protocol (Water Linked's public "Modem-M64 serial protocol", version 1.0.x): 115200 8N1, no flow
control; every sentence is ``w`` + direction (``c`` to the modem, ``r`` from it) + a command letter +
``,``-separated options + an optional ``*xx`` checksum (CRC-8, polynomial 0x07, initial value 0, over
everything before the ``*``, two lower-case hex digits) + LF or CR LF.  The modem always sends the
checksum; a host may leave it out.  ``wcq,<size>,<payload>`` and ``wrp,<size>,<payload>`` carry
``size`` raw bytes that may hold anything (``,``, ``*``, CR, LF): they are framed by that length here,
never by the line (``wlmodem`` reads them the same way; without the checksum it would take a payload
whose 6th byte is ``*`` for one, which is why the modem always sends it).

Two codecs, one per side (as h11): :class:`ModemCodec` turns a host's bytes into :class:`Command`
events and builds the modem's answers; :class:`HostCodec` turns the modem's bytes into
:class:`Response`, :class:`Packet` and :class:`Refused` events and builds commands.  A sentence that
cannot be understood is :class:`Malformed` (the modem answers ``wr?``), one whose checksum does not
match is :class:`BadChecksum` (``wr!``); neither stops the codec.

The datagram framing is the one of ``wlmodem``'s ``WlUDPSocket``, so that a datagram application on
the far modem understands hilgate's frames and the other way round: a datagram is followed by its
CRC-8, COBS/R-encoded (Consistent Overhead Byte Stuffing, Reduced: no zero byte inside) and ended by a
zero byte; the stream is cut into packets of the modem's payload size (8 bytes for the M64), the last
one padded with empty frames (``01 00``, or a lone ``00``).  :func:`frame` / :class:`Deframer`.  An
all-zero packet is reserved by the modem (its sync packet, never delivered): the framing never makes one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

SOP = ord("w")
LF, CR = ord("\n"), ord("\r")
MAX_SENTENCE = 64
"""Longest sentence either side sends (``wcq,8,<8 bytes>*xx``: 14 bytes); longer lines are noise."""
MAX_PAYLOAD = 255
"""Largest ``<size>`` the codecs accept in ``wcq``/``wrp`` (the M64's is 8; a larger one is refused by
the modem, not by the codec)."""
PAYLOAD_COMMANDS = (ord("q"), ord("p"))
END = 0
MAX_DATAGRAM = 4096
"""Bytes a :class:`Deframer` holds waiting for a datagram's end before it gives it up (noise)."""


def crc8(data: bytes, crc: int = 0) -> int:
    """CRC-8 with polynomial 0x07, initial value 0, no reflection: the M64's checksum and the CRC
    ``WlUDPSocket`` appends to each datagram."""
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def checksum(sentence: bytes) -> bytes:
    return b"*%02x" % crc8(sentence)


def sentence(direction: bytes, letter: bytes, *options: bytes, with_checksum: bool = True) -> bytes:
    """``w`` + direction + letter + ``,option…`` + ``*xx`` (unless asked not to) + LF."""
    body = b"w" + direction + letter + b"".join(b"," + option for option in options)
    return body + (checksum(body) if with_checksum else b"") + b"\n"


# -- events ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Command:
    """A host's command: ``letter`` (``v``, ``n``, ``c``, ``s``, ``l``, ``f``, ``d``, ``q``…), its
    ``options`` (text fields) and, for ``wcq``, the raw ``payload``; ``checked``: it carried a checksum."""

    letter: str
    options: tuple[str, ...] = ()
    payload: bytes | None = None
    checked: bool = False


@dataclass(frozen=True)
class Response:
    """The modem's answer to a command (``wrv``, ``wrn``, ``wrc``, ``wrs``, ``wrl``, ``wrf``, ``wrd``,
    ``wrq``…): ``letter`` and ``options``."""

    letter: str
    options: tuple[str, ...] = ()

    @property
    def ack(self) -> bool:
        return self.options[:1] == ("a",)


@dataclass(frozen=True)
class Packet:
    """``wrp``: a packet from the other modem."""

    payload: bytes


@dataclass(frozen=True)
class Refused:
    """``wr?`` (the modem could not understand a command: ``malformed``) or ``wr!`` (its checksum did
    not match: ``checksum``)."""

    reason: str


@dataclass(frozen=True)
class Malformed:
    """Bytes that make no sentence, with why (the modem answers them ``wr?``)."""

    reason: str
    data: bytes = b""


@dataclass(frozen=True)
class BadChecksum:
    """A sentence whose ``*xx`` does not match its bytes (the modem answers ``wr!``)."""

    data: bytes = b""


# -- the sentence splitter both sides share ----------------------------------------------------------


@dataclass
class _Splitter:
    """Cuts a byte stream into sentences: up to LF (a CR before it is dropped), or, for ``?q``/``?p``,
    ``<size>`` raw bytes after the size field and then up to LF."""

    direction: int  # the direction byte this side receives: c (modem side) or r (host side)
    buffer: bytearray = field(default_factory=bytearray)

    def split(self, data: bytes) -> list[object]:
        self.buffer += data
        out: list[object] = []
        while True:
            item = self._next()
            if item is None:
                return out
            out.append(item)

    def _next(self) -> object | None:
        buffer = self.buffer
        while buffer[:1] in (b"\n", b"\r"):  # empty lines (wlmodem sends one to start afresh)
            del buffer[:1]
        if not buffer:
            return None
        if buffer[0] != SOP:
            return self._noise()
        size_end = self._payload_end()
        if size_end is _INCOMPLETE:
            return None
        return self._sentence(size_end)

    def _noise(self) -> Malformed | None:
        """Bytes before a sentence's start: up to the line end (or a ``w`` that starts one) as Malformed, or
        None to wait for more."""
        buffer = self.buffer
        end = _line_end(buffer, 0)
        if end < 0:
            if len(buffer) > MAX_SENTENCE:
                data = bytes(buffer)
                buffer.clear()
                return Malformed("no sentence", data)
            # wait for the line end, unless a sentence starts in the noise
            start = buffer.find(b"w")
            if start > 0:
                data = bytes(buffer[:start])
                del buffer[:start]
                return Malformed("no sentence", data)
            return None
        data = bytes(buffer[:end])
        del buffer[:end + 1]
        return Malformed("no sentence", data)

    def _payload_end(self) -> int | None | object:
        """Where a ``w?q,<size>,<payload>`` sentence's payload ends (it is framed by its length, not by a
        line end); None for a sentence without one, _INCOMPLETE while the size or payload is still coming."""
        buffer = self.buffer
        if not (len(buffer) >= 3 and buffer[2] in PAYLOAD_COMMANDS and buffer[1] == self.direction):
            return None
        comma = buffer.find(b",", 4, 8)
        if len(buffer) < 4:
            return _INCOMPLETE
        if buffer[3] != ord(","):
            return None
        if comma < 0:
            if len(buffer) < 8 and _line_end(buffer, 0) < 0:
                return _INCOMPLETE
            return None
        digits = bytes(buffer[4:comma])
        if digits.isdigit() and int(digits) <= MAX_PAYLOAD:
            size_end = comma + 1 + int(digits)
            if len(buffer) < size_end:
                return _INCOMPLETE
            return size_end
        return None

    def _sentence(self, size_end: int | None) -> object | None:
        """The sentence at the buffer's start, up to its line end (after the payload, if it has one), or
        None to wait for more."""
        buffer = self.buffer
        longest = MAX_SENTENCE + (MAX_PAYLOAD if size_end is not None else 0)
        end = _line_end(buffer, size_end if size_end is not None else 0)
        if end < 0:
            if len(buffer) > longest:
                data = bytes(buffer)
                buffer.clear()
                return Malformed("too long", data)
            return None
        line = bytes(buffer[:end])
        del buffer[:end + 1]
        if line.endswith(b"\r") and (size_end is None or len(line) > size_end):
            # the CR of a CR LF line end; a payload's own last byte may be CR (wlmodem sends no checksum
            # after it), and the payload was framed by its length: that CR is the payload's
            line = line[:-1]
        if len(line) > longest:
            return Malformed("too long", line)
        return _parse(line, size_end, self.direction)


_INCOMPLETE = object()  # _Splitter._payload_end's answer while a payload's size or bytes are still coming


def _line_end(buffer: bytearray, start: int) -> int:
    return buffer.find(b"\n", start)


def _parse(line: bytes, payload_end: int | None, direction: int) -> object:
    """One sentence (without its LF) → (letter, options, payload, checked) or a Malformed/BadChecksum."""
    if len(line) < 3:
        return Malformed("too short", line)
    if line[1] != direction:
        return Malformed("wrong direction", line)
    head_end = payload_end if payload_end is not None else len(line)
    tail = line[head_end:] if payload_end is not None else b""
    checked = False
    if payload_end is not None:
        body = line[:payload_end]
        if tail:
            if len(tail) != 3 or tail[:1] != b"*":
                return Malformed("bytes after the payload", line)
            if tail[1:] != checksum(body)[1:]:
                return BadChecksum(line)
            checked = True
        digits_start = 4
        comma = body.find(b",", digits_start)
        payload = body[comma + 1:]
        options = (body[digits_start:comma].decode("ascii"),)
        return (chr(line[2]), options, payload, checked)
    body = line
    star = line.rfind(b"*")
    if star >= 0 and star == len(line) - 3:
        body = line[:star]
        if line[star:].lower() != checksum(body):
            return BadChecksum(line)
        checked = True
    elif star >= 0:
        return Malformed("a * that is no checksum", line)
    try:
        text = body.decode("ascii")
    except UnicodeDecodeError:
        return Malformed("not ASCII", line)
    if not text[2].isalpha() and text[2] not in "?!":
        return Malformed("no command letter", line)
    if len(text) > 3 and text[3] != ",":
        return Malformed("no comma after the command letter", line)
    options = tuple(text[4:].split(",")) if len(text) > 3 else ()
    return (text[2], options, None, checked)


# -- the two sides -----------------------------------------------------------------------------------


@dataclass
class ModemCodec:
    """The modem's side: a host's bytes → :class:`Command`, :class:`Malformed`, :class:`BadChecksum`;
    answers (always with their checksum) → bytes."""

    _splitter: _Splitter = field(default_factory=lambda: _Splitter(ord("c")))

    def receive_data(self, data: bytes) -> list[object]:
        events: list[object] = []
        for item in self._splitter.split(data):
            if isinstance(item, tuple):
                letter, options, payload, checked = item
                events.append(Command(letter, options, payload, checked))
            else:
                events.append(item)
        return events

    @staticmethod
    def response(letter: str, *options: str) -> bytes:
        return sentence(b"r", letter.encode("ascii"), *(o.encode("ascii") for o in options))

    @staticmethod
    def packet(payload: bytes) -> bytes:
        return sentence(b"r", b"p", b"%d" % len(payload), payload)

    @staticmethod
    def refusal(event: object) -> bytes:
        """``wr!`` for a bad checksum, ``wr?`` for anything else it could not understand."""
        return sentence(b"r", b"!" if isinstance(event, BadChecksum) else b"?")


@dataclass
class HostCodec:
    """The host's side: the modem's bytes → :class:`Response`, :class:`Packet`, :class:`Refused`,
    :class:`Malformed`, :class:`BadChecksum`; commands → bytes (with a checksum unless asked not to)."""

    with_checksum: bool = True
    _splitter: _Splitter = field(default_factory=lambda: _Splitter(ord("r")))

    def receive_data(self, data: bytes) -> list[object]:
        events: list[object] = []
        for item in self._splitter.split(data):
            if not isinstance(item, tuple):
                events.append(item)
                continue
            letter, options, payload, _ = item
            if letter == "p":
                if payload is None:
                    events.append(Malformed("a packet without its payload"))
                else:
                    events.append(Packet(payload))
            elif letter == "?":
                events.append(Refused("malformed"))
            elif letter == "!":
                events.append(Refused("checksum"))
            else:
                events.append(Response(letter, options))
        return events

    def command(self, letter: str, *options: str) -> bytes:
        return sentence(b"c", letter.encode("ascii"), *(o.encode("ascii") for o in options),
                        with_checksum=self.with_checksum)

    def queue(self, payload: bytes) -> bytes:
        return sentence(b"c", b"q", b"%d" % len(payload), payload, with_checksum=self.with_checksum)


# -- WlUDPSocket's datagram framing --------------------------------------------------------------------


def cobsr_encode(data: bytes) -> bytes:
    """COBS/R: as COBS (each block of non-zero bytes is preceded by its length + 1, a zero ends a
    block), except that when the last block's final byte is at least its length code, that byte
    replaces the code and is dropped from the end (one byte saved)."""
    out = bytearray()
    block = bytearray()
    for byte in data:
        if byte == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
    code = len(block) + 1
    if block and block[-1] >= code:
        out.append(block[-1])
        out += block[:-1]
    else:
        out.append(code)
        out += block
    return bytes(out)


class DecodeError(ValueError):
    pass


def cobsr_decode(data: bytes) -> bytes:
    out = bytearray()
    i = 0
    n = len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise DecodeError("zero byte inside a COBS/R frame")
        i += 1
        end = i + code - 1
        block = data[i:end]
        if 0 in block:
            raise DecodeError("zero byte inside a COBS/R frame")
        if end > n:  # the reduced last block: its code was its final byte
            out += block
            out.append(code)
            return bytes(out)
        out += block
        i = end
        if i < n and code != 255:
            out.append(0)
    return bytes(out)


def frame(datagram: bytes) -> bytes:
    """A datagram as ``WlUDPSocket`` sends it: COBS/R of (datagram + CRC-8), then a zero byte."""
    return cobsr_encode(datagram + bytes([crc8(datagram)])) + b"\x00"


def packets(stream: bytes, size: int = 8) -> list[bytes]:
    """Cut framed bytes into packets of ``size``, the last padded as ``WlUDPSocket`` pads it (empty
    COBS frames ``01 00``, then a lone ``00`` if one byte is left)."""
    out = []
    for start in range(0, len(stream), size):
        piece = bytearray(stream[start:start + size])
        while size - len(piece) >= 2:
            piece += b"\x01\x00"
        if len(piece) < size:
            piece.append(0)
        out.append(bytes(piece))
    return out


@dataclass(frozen=True)
class Datagram:
    data: bytes


@dataclass(frozen=True)
class BadDatagram:
    """Bytes between two frame ends that are no datagram: ``cobs`` (not COBS/R), ``crc`` (a packet of it
    was lost or damaged on the way), ``overlong`` (no frame end within :data:`MAX_DATAGRAM` bytes)."""

    reason: str
    size: int


@dataclass
class Deframer:
    """Packets from the modem → :class:`Datagram` and :class:`BadDatagram` events (padding frames are
    skipped).  A lost packet damages the datagram it was part of, which then fails its CRC."""

    buffer: bytearray = field(default_factory=bytearray)

    def receive_packet(self, payload: bytes) -> list[object]:
        self.buffer += payload
        events: list[object] = []
        while True:
            end = self.buffer.find(b"\x00")
            if end < 0:
                if len(self.buffer) > MAX_DATAGRAM:
                    events.append(BadDatagram("overlong", len(self.buffer)))
                    self.buffer.clear()
                return events
            chunk = bytes(self.buffer[:end])
            del self.buffer[:end + 1]
            if not chunk:
                continue  # a lone 00 of padding
            try:
                decoded = cobsr_decode(chunk)
            except DecodeError:
                events.append(BadDatagram("cobs", len(chunk)))
                continue
            if not decoded:
                continue  # an empty frame: padding
            data, crc = decoded[:-1], decoded[-1]
            if crc8(data) != crc:
                events.append(BadDatagram("crc", len(chunk)))
                continue
            events.append(Datagram(data))
