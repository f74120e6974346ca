"""EvoLogics S2C AT protocol, without I/O: a host-side and a modem-side codec.

Everything here is rebuilt from public drivers (see ``shared/protocols/evologics-at.md``): bytes go
in with ``receive_data``, typed events come out of ``next_events``; commands, replies and
notifications go out as bytes.  The same codecs serve hilgate's driver (host side), its emulator
(modem side) and the fuzz tests.  Parsing follows EvoLogics' own EVINS stack:

- modem → host lines end with CR LF; the host may end its lines with CR, LF or CR LF;
- SEND*/RECV* carry ``<len>`` and then exactly ``len`` raw bytes (which may hold ``,``, CR, LF, NUL or
  ``+++AT``): they are framed by length, never by line; an optional ``p<pid>`` follows the keyword;
- in data mode, replies are ``+++AT<cmd>:<n>:<body>`` and notifications ``+++AT:<n>:<body>``, cut out
  by their length; everything else is raw burst data; a trailing ``+``, ``++``, ``+++A``… is held back
  until the next bytes tell whether it starts an escape frame;
- ``ERROR EFAULT`` and ``ERROR OVERLOAD`` are unsolicited; other ``ERROR``/``BUSY`` lines answer the
  command in flight; ``AT&V``-style answers run to an empty line;
- RECVIM from firmware 1.6 (``bitrate,rssi,int,ptime,vel`` instead of ``dur``) is recognised by where
  the CR LF falls after the payload.

Every problem the codecs report is an :class:`AtProtocolError`; anything else would be a bug.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

CRLF = b"\r\n"
ESCAPE = b"+++AT"
MAX_LINE = 4096

# Notifications and their number of fields between the keyword and the payload (without p<pid>).
PAYLOAD_FIELDS = {"RECVIM": 8, "RECVIMS": 8, "RECVPBM": 7, "RECV": 8}
ASYNC_PREFIXES = (
    "RECVIM", "RECVIMS", "RECVPBM", "RECV", "DELIVEREDIM", "FAILEDIM", "CANCELEDIM", "CANCELEDIMS", "CANCELEDPBM",
    "EXPIREDIMS", "DELIVERED", "FAILED", "SENDSTART", "SENDEND", "RECVSTART", "RECVEND", "RECVFAILED", "BITRATE",
    "SRCLEVEL", "PHYON", "PHYOFF", "RADDR", "DROPCNT", "RECVSRV", "STATUS", "ECLK", "RTO", "USBLLONG", "USBLANGLES",
    "USBLPHYD", "USBLPHYP", "RECVPROBE", "INITIATION",
)
UNSOLICITED_ERRORS = ("ERROR EFAULT", "ERROR OVERLOAD")
MULTILINE = ("&V", "?S", "?ZSL")
SEND_FIELDS = {"*SENDIM": 3, "*SENDIMS": 3, "*SENDPBM": 2, "*SEND": 2}  # fields before the payload


class AtProtocolError(ValueError):
    """The peer broke the protocol; the codec has skipped the offending bytes and can go on."""


# -- events ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Reply:
    """The answer to the command in flight: ``OK``, ``[*]OK``, ``ERROR …``, ``BUSY …``, a value, or
    several lines (``lines``) for multi-line answers."""

    command: str
    text: str
    lines: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.text in ("OK", "[*]OK")

    @property
    def error(self) -> str | None:
        if self.text.startswith(("ERROR", "BUSY")):
            return self.text
        return None


@dataclass(frozen=True)
class Notification:
    """An asynchronous line: ``name`` (RECVIM, DELIVEREDIM…), its comma-separated ``fields`` (without
    the name and the pid) and, for RECV*, the ``payload``."""

    name: str
    fields: tuple[str, ...]
    payload: bytes | None = None
    pid: int | None = None

    def field(self, index: int, default: str = "") -> str:
        return self.fields[index] if index < len(self.fields) else default


@dataclass(frozen=True)
class AsyncError:
    reason: str  # EFAULT, OVERLOAD


@dataclass(frozen=True)
class Data:
    """Raw burst data received in data mode."""

    payload: bytes


@dataclass(frozen=True)
class Unexpected:
    """A line that answers nothing (no command in flight) and is no known notification."""

    text: str


@dataclass(frozen=True)
class Command:
    """What a host sent (modem side): ``name`` like ``*SENDIM``, ``?T``, ``!AL``, ``O``, ``Z4``;
    ``args`` the text after it (``5`` for ``!AL5``), ``fields`` the comma-separated arguments of
    SEND commands, ``payload`` their data."""

    name: str
    args: str = ""
    fields: tuple[str, ...] = ()
    payload: bytes | None = None
    pid: int | None = None
    escaped: bool = False  # arrived as +++AT… (data mode)


@dataclass(frozen=True)
class BadCommand:
    """A line the modem cannot accept; the modem answers ``ERROR <reason>``."""

    reason: str
    text: str


HostEvent = Reply | Notification | AsyncError | Data | Unexpected | AtProtocolError
"""What the host side (a driver) gets from the modem's bytes; consumed with ``match``."""

ModemEvent = Command | BadCommand | Data
"""What the modem side (an emulator) gets from the host's bytes; consumed with ``match``."""


# -- helpers --------------------------------------------------------------------------------------

_PID = re.compile(rb"p(\d{1,3})$")  # a protocol id is 0..7: bounded, so int() never meets 5 000 digits


def _split_fields(header: bytes, count: int) -> list[bytes] | None:
    """The first ``count`` comma-separated fields of ``header`` (which starts after ``KEYWORD,``), or
    None if there are not that many commas yet."""
    fields = []
    start = 0
    for _ in range(count):
        comma = header.find(b",", start)
        if comma < 0:
            return None
        fields.append(header[start:comma])
        start = comma + 1
    return fields


def _ascii(data: bytes) -> str:
    return data.decode("latin-1")


def _payload_frame(buffer: bytes | bytearray, keyword: bytes, fields_before: int, length_index: int,
                   any_line_end: bool = False) -> tuple[int, list[bytes], bytes, int | None] | None:
    """Parse ``KEYWORD[,p<pid>],f1,…,fN,<payload>`` framed by the length field and a line end (CR LF
    from the modem; CR, LF or CR LF from a host when ``any_line_end``); returns (bytes consumed,
    fields, payload, pid) or None when more bytes are needed.  Raises AtProtocolError on a malformed
    header or a payload not followed by a line end."""
    start = len(keyword) + 1  # after "KEYWORD,"
    pid = None
    probe = buffer[start:start + 6]
    if probe[:1] == b"p":
        comma = buffer.find(b",", start)
        if comma < 0:
            if len(buffer) - start > 6:
                raise AtProtocolError(f"bad protocol id in {_ascii(bytes(buffer[:40]))!r}")
            return None
        match = _PID.match(bytes(buffer[start:comma]))
        if not match:
            raise AtProtocolError(f"bad protocol id in {_ascii(bytes(buffer[:40]))!r}")
        pid = int(match.group(1))
        start = comma + 1
    header = bytes(buffer[start:start + 200])
    fields = _split_fields(header, fields_before)
    # The fields before the payload are text on one line: a line end among them (``AT*SENDIM,5,1,ack``
    # and Enter, without the data's comma) ends a malformed command now, rather than letting the length
    # framing run on into the next commands in search of the missing commas.
    end_of_fields = sum(len(f) + 1 for f in fields) if fields is not None else len(header)
    line_end = next((i for i in (header.find(b"\r", 0, end_of_fields), header.find(b"\n", 0, end_of_fields))
                     if i >= 0), -1)
    if line_end >= 0:
        raise AtProtocolError(f"{_ascii(keyword)}: a line end before its {fields_before} fields and the data")
    if fields is None:
        if len(buffer) - start > 200:
            raise AtProtocolError(f"header too long: {_ascii(bytes(buffer[:40]))!r}")
        return None
    length_text = fields[length_index]
    if not length_text.isdigit() or len(length_text) > 5:
        raise AtProtocolError(f"bad length {length_text!r}")
    length = int(length_text)
    data_start = start + sum(len(f) + 1 for f in fields)
    after = data_start + length
    payload = bytes(buffer[data_start:after])
    if any_line_end:
        # a lone CR ends the line at once; an LF right behind it is skipped later as an empty line
        if len(buffer) <= after:
            return None
        if buffer[after] in (0x0D, 0x0A):
            return after + 1, fields, payload, pid
    else:
        if len(buffer) < after + 2:
            return None
        if buffer[after:after + 2] == CRLF:
            return after + 2, fields, payload, pid
    raise AtProtocolError(f"{_ascii(keyword)}: {length} bytes of data not followed by the line end")


def _recv_keyword(buffer: bytes | bytearray) -> str | None | bool:
    """RECVIM/RECVIMS/RECVPBM/RECV at the start of ``buffer``: its name; None if the comma that
    tells has not arrived yet; False for anything else (RECVSTART, RECVEND…: plain lines)."""
    comma = buffer.find(b",", 0, 12)
    if comma < 0:
        if len(buffer) < 12 and buffer.find(b"\r", 0, 12) < 0:
            return None
        return False
    name = _ascii(bytes(buffer[:comma]))
    return name if name in PAYLOAD_FIELDS else False


def _parse_recv(buffer: bytes | bytearray) -> tuple[int, Notification] | None:
    """A RECV* notification at the start of ``buffer`` (None: need more bytes)."""
    keyword = bytes(buffer[: buffer.find(b",")]) if b"," in buffer[:12] else b""
    name = _ascii(keyword)
    if name not in PAYLOAD_FIELDS:
        return None
    counts = [PAYLOAD_FIELDS[name]]
    if name == "RECVIM":
        counts.append(9)  # firmware 1.6: bitrate,rssi,int,ptime,vel instead of dur
    last_error = None
    for count in counts:
        try:
            parsed = _payload_frame(buffer, keyword, count, 0)
        except AtProtocolError as exc:
            last_error = exc
            continue
        if parsed is None:
            return None
        consumed, fields, payload, pid = parsed
        return consumed, Notification(name, tuple(_ascii(f) for f in fields), payload, pid)
    raise last_error or AtProtocolError(f"bad {name}")


def _data_before_escape(buffer: bytearray) -> Data | None:
    """In data mode: take the raw burst bytes before the next ``+++AT``, holding back a tail that may
    be the start of one (``+``, ``++``, ``+++A``) until the next bytes tell."""
    at = buffer.find(ESCAPE)
    if at < 0:
        keep = next((n for n in range(min(len(ESCAPE) - 1, len(buffer)), 0, -1) if buffer.endswith(ESCAPE[:n])), 0)
        at = len(buffer) - keep
    if at <= 0:
        return None
    data = bytes(buffer[:at])
    del buffer[:at]
    return Data(data)


def _classify(line: str) -> str:
    """notification | async_error | reply"""
    if line in UNSOLICITED_ERRORS:
        return "async_error"
    head = line.split(",", 1)[0]
    if head in ASYNC_PREFIXES or (line.startswith("%") and "," in line) or (head.startswith("INITIATION")):
        return "notification"
    return "reply"


def _notification(line: str) -> Notification:
    parts = line.split(",")
    pid = None
    fields = parts[1:]
    if fields and re.fullmatch(r"p\d{1,3}", fields[0]) and parts[0] in PAYLOAD_FIELDS:
        pid = int(fields[0][1:])
        fields = fields[1:]
    return Notification(parts[0], tuple(fields), None, pid)


# -- host side ------------------------------------------------------------------------------------


@dataclass
class HostCodec:
    """The host's view: commands out, replies/notifications/data in.

    ``eol`` is what the host sends after a command: ``\\r`` on serial, ``\\n`` on TCP (the modem's
    own interfaces are configured so).  ``data_mode`` is switched by :meth:`command` for ``ATO`` and
    ``+++ATC``."""

    eol: bytes = b"\r"
    data_mode: bool = False
    pending: str | None = None
    _buffer: bytearray = field(default_factory=bytearray)
    _lines: list[str] = field(default_factory=list)

    def command(self, name: str, args: str = "", payload: bytes | None = None, fields: tuple = ()) -> bytes:
        """Bytes for ``AT<name><args>`` (SEND commands: ``fields`` then the payload with its length)."""
        body = self._body(name, args, payload, fields)
        prefix = b"+++AT" if self.data_mode else b"AT"
        self.pending = name
        self._lines = []
        if name == "O" and not self.data_mode:
            self.data_mode = True
            self.pending = None  # ATO has no reply
        elif name == "C" and self.data_mode:
            self.data_mode = False
        return prefix + body + self.eol

    @staticmethod
    def _body(name: str, args: str, payload: bytes | None, fields: tuple) -> bytes:
        if payload is None:
            return (name + args).encode("latin-1")
        parts = [str(len(payload))] + [str(f) for f in fields]
        return (name + "," + ",".join(parts) + ",").encode("latin-1") + payload

    def raw(self, payload: bytes) -> bytes:
        """Burst data in data mode is sent as is."""
        return payload

    def timeout(self) -> None:
        """The command in flight got no answer: forget it."""
        self.pending = None
        self._lines = []

    def receive_data(self, data: bytes) -> list[HostEvent]:
        self._buffer += data
        events: list = []
        while True:
            try:
                event = self._next()
            except AtProtocolError as exc:
                self._resync()
                events.append(exc)
                continue
            if event is None:
                break
            if event is not _SKIP:
                events.append(event)
        if len(self._buffer) > 65536:  # a runaway peer: drop what cannot be a frame
            self._buffer.clear()
            events.append(AtProtocolError("receive buffer overflow"))
        return events

    def _resync(self) -> None:
        """Skip to the next line end (or one byte) after a malformed frame."""
        end = self._buffer.find(CRLF)
        del self._buffer[: end + 2 if end >= 0 else max(1, len(self._buffer))]

    def _next(self) -> object | None:
        buffer = self._buffer
        if not buffer:
            return None
        if self.data_mode:
            return self._next_data_mode()
        if buffer[:2] == CRLF:
            del buffer[:2]
            return self._line("")
        keyword = _recv_keyword(buffer) if buffer[:4] == b"RECV" else False
        if keyword is None:
            return None  # "RECV…" without its comma yet
        if keyword:
            parsed = _parse_recv(buffer)
            if parsed is None:
                if len(buffer) > 70000:
                    raise AtProtocolError("RECV frame never completes")
                return None
            consumed, notification = parsed
            del buffer[:consumed]
            return notification
        end = buffer.find(CRLF)
        if end < 0:
            if len(buffer) > MAX_LINE:
                raise AtProtocolError("line too long")
            return None
        line = _ascii(bytes(buffer[:end]))
        del buffer[: end + 2]
        return self._line(line)

    def _line(self, line: str) -> object:
        if line == "":
            if self.pending in MULTILINE and self._lines:
                lines = tuple(self._lines)
                command, self.pending, self._lines = self.pending, None, []
                return Reply(command, lines[0], lines)
            return _SKIP  # stray blank line
        kind = _classify(line)
        if kind == "async_error":
            return AsyncError(line.split(" ", 1)[1])
        if kind == "notification":
            return _notification(line)
        if self.pending is None:
            return Unexpected(line)
        if self.pending in MULTILINE and not line.startswith(("ERROR", "BUSY")):
            self._lines.append(line)
            return _SKIP
        command, self.pending = self.pending, None
        return Reply(command, line)

    def _next_data_mode(self) -> object | None:
        buffer = self._buffer
        if not buffer.startswith(ESCAPE):
            return _data_before_escape(buffer)
        match = re.match(rb"\+\+\+AT([^:\r\n]{0,16}):(\d{1,5}):", bytes(buffer[:40]))
        if match is None:
            if re.fullmatch(rb"\+\+\+AT[^:\r\n]{0,16}(:\d{0,5})?", bytes(buffer[:40])):
                return None  # need more bytes
            # "+++AT" not followed by ...:<digits>: is raw data (as EVINS does)
            del buffer[:1]
            return Data(b"+")
        length = int(match.group(2))
        start = match.end()
        end = start + length + 2
        if len(buffer) < end:
            return None
        if buffer[end - 2:end] != CRLF:
            raise AtProtocolError(f"escape frame of {length} bytes not followed by CR LF")
        body = bytes(buffer[start:start + length])
        del buffer[:end]
        request = _ascii(match.group(1))
        if request == "":
            if body[:4] == b"RECV":
                parsed = _parse_recv(body + CRLF)
                if parsed is None:
                    raise AtProtocolError(f"truncated {_ascii(body[:10])}")
                return parsed[1]
            line = _ascii(body)
            if line in UNSOLICITED_ERRORS:
                return AsyncError(line.split(" ", 1)[1])
            return _notification(line)
        self.pending = None  # in data mode every +++AT<cmd>: frame answers the command in flight
        text = _ascii(body)
        lines = tuple(text.replace("\r\n", "\n").split("\n"))
        return Reply(request, lines[0] if lines else "", lines if len(lines) > 1 else ())


_SKIP = object()


# -- modem side -----------------------------------------------------------------------------------


@dataclass
class ModemCodec:
    """The modem's view: commands in (any line ending), replies and notifications out.

    Starts in command mode like a modem just powered on; ``ATO`` enters data mode, ``+++ATC`` (or
    ``+++ATO`` is ignored) leaves it.  In data mode, bytes outside ``+++AT…`` lines are burst data."""

    data_mode: bool = False
    _buffer: bytearray = field(default_factory=bytearray)

    def receive_data(self, data: bytes) -> list[ModemEvent]:
        self._buffer += data
        events: list = []
        while True:
            event = self._next()
            if event is None:
                break
            events.append(event)
        if len(self._buffer) > 65536:
            self._buffer.clear()
            events.append(BadCommand("BUFFER FULL", "input overflow"))
        return events

    def _next(self) -> object | None:
        buffer = self._buffer
        while buffer[:1] in (b"\r", b"\n"):
            del buffer[:1]
        if not buffer:
            return None
        if self.data_mode:
            if not buffer.startswith(ESCAPE):
                return _data_before_escape(buffer)
            return self._command(escaped=True)
        if buffer[:5] == ESCAPE:
            parsed = self._command(escaped=True)
            if parsed is None:
                return None
            if isinstance(parsed, Command) and parsed.name == "C":
                return parsed  # +++ATC is harmless in command mode
            return BadCommand("WRONG FORMAT", "+++AT in command mode")
        if buffer[:2].upper() != b"AT":
            end = self._line_end(0)
            if end is None:
                if len(buffer) > MAX_LINE:
                    buffer.clear()
                    return BadCommand("WRONG FORMAT", "line too long")
                return None
            text = _ascii(bytes(buffer[: end[0]]))
            del buffer[: end[1]]
            return BadCommand("WRONG FORMAT", text)
        return self._command(escaped=False)

    def _line_end(self, start: int) -> tuple[int, int] | None:
        """(end of the text, end of the line ending) for a line starting at ``start``."""
        buffer = self._buffer
        for index in range(start, len(buffer)):
            byte = buffer[index]
            if byte == 0x0D:
                if index + 1 < len(buffer) and buffer[index + 1] == 0x0A:
                    return index, index + 2
                if index + 1 == len(buffer):
                    return index, index + 1  # a lone CR ends the line; a following LF is skipped later
                return index, index + 1
            if byte == 0x0A:
                return index, index + 1
        return None

    def _command(self, escaped: bool) -> object | None:
        buffer = self._buffer
        prefix = 5 if escaped else 2
        # SEND commands carry a length-framed payload
        for name, fields_before in SEND_FIELDS.items():
            keyword = name.encode()
            if buffer[prefix:prefix + len(keyword) + 1] == keyword + b",":
                sub = bytes(buffer[prefix:])
                try:
                    parsed = _payload_frame(sub, keyword, fields_before, 0, any_line_end=True)
                except AtProtocolError as exc:
                    end = self._line_end(prefix)
                    if end is None:
                        return None
                    text = _ascii(bytes(buffer[: end[0]]))
                    del buffer[: end[1]]
                    return BadCommand("WRONG FORMAT", f"{text} ({exc})")
                if parsed is None:
                    if len(buffer) > 2000:
                        end = self._line_end(prefix)
                        cut = end[1] if end else len(buffer)
                        del buffer[:cut]
                        return BadCommand("WRONG FORMAT", f"{name} payload never completes")
                    return None
                consumed, fields, payload, pid = parsed
                del buffer[: prefix + consumed]
                return Command(name, "", tuple(_ascii(f) for f in fields), payload, pid, escaped)
        end = self._line_end(prefix)
        if end is None:
            if len(buffer) > MAX_LINE:
                buffer.clear()
                return BadCommand("WRONG FORMAT", "line too long")
            return None
        text = _ascii(bytes(buffer[prefix:end[0]]))
        del buffer[: end[1]]
        if escaped and text == "C":
            self.data_mode = False
            return Command("C", escaped=True)
        match = re.fullmatch(r"([?!@&%*]?[A-Za-z]{1,5}\$?)(.*)", text)
        if not text:
            return Command("", escaped=escaped)  # plain "AT": answered OK
        if match is None:
            return BadCommand("WRONG FORMAT", text)
        name, args = match.group(1), match.group(2)
        if name == "O" and not escaped:
            self.data_mode = True
        return Command(name.upper() if name[0].isalpha() else name[0] + name[1:].upper(), args, escaped=escaped)

    # -- modem → host --------------------------------------------------------------------------

    def reply(self, command: Command, text: str) -> bytes:
        if command.escaped or self.data_mode:
            body = text.encode("latin-1")
            return b"+++AT" + command.name.encode("latin-1") + b":" + str(len(body)).encode() + b":" + body + CRLF
        return text.encode("latin-1") + CRLF

    def error(self, command: Command | None, reason: str) -> bytes:
        if command is None:
            return self.notify_line(f"ERROR {reason}")
        return self.reply(command, f"ERROR {reason}")

    def notify_line(self, text: str, payload: bytes | None = None) -> bytes:
        """A notification: ``text`` then, for RECV*, the payload (``text`` already ends with its comma)."""
        body = text.encode("latin-1") + (payload if payload is not None else b"")
        if self.data_mode:
            return b"+++AT:" + str(len(body)).encode() + b":" + body + CRLF
        return body + CRLF

    @staticmethod
    def recvim(src: int, dst: int, payload: bytes, ack: bool, duration_us: int, rssi: int, integrity: int,
               velocity: float, pid: int | None = None) -> tuple[str, bytes]:
        pid_text = f"p{pid}," if pid is not None else ""
        return (f"RECVIM,{pid_text}{len(payload)},{src},{dst},{'ack' if ack else 'noack'},{duration_us},{rssi},"
                f"{integrity},{velocity:.2f},", payload)

    @staticmethod
    def recv_burst(src: int, dst: int, payload: bytes, bitrate: int, rssi: int, integrity: int, ptime_us: int,
                   velocity: float) -> tuple[str, bytes]:
        return (f"RECV,{len(payload)},{src},{dst},{bitrate},{rssi},{integrity},{ptime_us},{velocity:.2f},", payload)
