"""What daemons tell each other over Zenoh, as bytes: transmissions, poses, host announcements.  No I/O.

A **transmission** is one frame going on air on the sender's host: enough for every other host's
medium to hand out its arrivals exactly as the sender's own medium does (frame, start, duration,
the sender's position at the start) and for the receiving applications to get the frame back
(the application's packet and what the receiving modem needs to print it).  Binary, big-endian (it is
on every frame's path across hosts, where JSON cost a third of the round trip)::

    u8 version (4) | u8 flags (1 position, 2 served frame, 4 application frame) | i64 epoch_ns |
    u64 number | f64 t | f64 duration | f64 x, y, z | name host | name session | frame |
    [frame served] | [application frame] | u32 CRC-32 of all before
    frame:             i64 id | i16 src addr | u16 dst addr | u32 size | f64 t0 | i64 seq |
                       u16 ACK retries (0xFFFF: none) | name src link | name dst link | name kind
    application frame: i64 seq | i16 src | u16 dst | f64 t0 | u32 meta length | u32 real length |
                       u32 payload length | u32 payload offset in the real packet (0xFFFFFFFF: the
                       payload follows it) | name packet class | meta (JSON object, or nothing) |
                       real packet | [payload]
    name:              u16 length | UTF-8

The payload is sent once: it is a slice of the real packet for every packet class hilgate knows
(version 3 sent it twice, 2 kB more of a 2 kB frame's 4.3 kB message to encrypt, copy and check).

``epoch_ns`` is the sender's epoch (ns of the UNIX clock at its model time 0), ``session`` the sender's
Zenoh session id (new at every start), ``number`` the session's message counter (gaps are frames Zenoh
dropped; a number seen before is a replay: :class:`ReplayWindow`), ``t`` the start in the sender's model
time, ``kind`` a MAC's word (``data``, ``rts``, ``cts``, ``ack``, ``modem_ack``); the served frame is the one
a control frame or an acoustic ACK answers.  What is refused (:class:`NetError`, counted, never raised
into the loop): a message longer than :data:`MAX_TRANSMISSION` (before anything is read), one whose
CRC does not match (``damaged``: bits changed on the way; TLS keeps outsiders from doing it on
purpose, the CRC catches the rest), one of another version (the hosts of one network run the same
hilgate), and any field out of range: names are link ids (letters, digits, ``_ . -``), kinds lowercase
words, numbers finite; so nothing from another host reaches the trace unchecked.  (The names a host
sends are the same from frame to frame: each is checked once and remembered, :data:`NAMES_KEPT` of them.)

A **pose** is UTF-8 JSON ``{"h", "e", "v" vehicle, "t" measured (sender's model time), "p" [x, y, z],
"u" velocity or null}``.  Model times convert between hosts through the epochs:
``t_here = t_there + (e_there − e_here)·1e-9`` (the daemons run at the same speed, 1).
"""

from __future__ import annotations

import functools
import json
import math
import re
import struct
import zlib
from dataclasses import dataclass
from typing import Any

from ..core import safejson
from ..core.backend import AppFrame
from ..core.packets import Raw, packet_class
from ..models.frame import Frame

__all__ = ["Transmission", "encode_transmission", "decode_transmission", "encode_pose", "decode_pose",
           "NetError", "to_local", "ReplayWindow", "MAX_TRANSMISSION", "TIME_WINDOW_S"]

MAX_HEADER = 16384
MAX_DURATION_S = 3600.0  # a frame longer on air than this is not one a modem sends
MAX_TRANSMISSION = 65536
"""Bytes of the longest transmission (a 2 kB payload, its packet, a served frame and the largest meta
JSON take under 24 kB): a longer message is refused before it is read."""
LINK_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,200}|\*")  # a link id (scene.links.LINK_ID), or * (broadcast)
KIND = re.compile(r"[a-z][a-z0-9_]{0,31}")
PACKET_NAME = re.compile(r"[A-Za-z0-9_.:-]{1,64}")  # (simple:N has a colon)
SESSION = re.compile(r"[0-9a-f]{1,32}")
TIME_WINDOW_S = 60.0  # another host's transmission or pose further from now than this (to_local) is dropped (counted)


class NetError(ValueError):
    """A message from another host that cannot be read (counted, never raised into the loop).
    ``cause`` is the counter it goes to: ``bad_message`` or ``damaged``."""

    def __init__(self, message: str, cause: str = "bad_message"):
        super().__init__(message)
        self.cause = cause


@dataclass
class Transmission:
    host: str
    epoch_ns: int
    number: int
    frame: Frame
    t: float
    duration: float
    position: tuple[float, float, float] | None
    ref_key: tuple[str, int] | None = None  # the served frame, to be matched with one this host knows
    session: str = ""


def to_local(t_there: float, epoch_there_ns: int, epoch_here_ns: int) -> float:
    """A model time of another host as this host's model time (both at speed 1)."""
    return t_there + (epoch_there_ns - epoch_here_ns) * 1e-9


# -- transmissions: a binary layout (JSON cost 25 + 36 µs a frame, a third of a cross-host round trip) --

VERSION = 4
_CRC = struct.Struct(">I")
_FIXED = struct.Struct(">BBqQddddd")       # version, flags, epoch_ns, number, t, duration, x, y, z
_FRAME = struct.Struct(">qhHIdqH")          # id, src_addr, dst_addr, size, t0, seq, ack retries (0xFFFF: none)
_APP = struct.Struct(">qhHdIIII")           # seq, src, dst, t0, meta length, real length, payload length, offset
_NAME = struct.Struct(">H")
HAS_POSITION, HAS_REF, HAS_APP = 1, 2, 4
NO_ACK = 0xFFFF
FOLLOWS = 0xFFFFFFFF  # the payload is not a slice of the real packet: it follows it
MAX_NAME = 256
NAMES_KEPT = 1024
"""Names remembered, encoded (this host's) and checked (the others'): a host's link ids, kinds, packet
classes and session are a few dozen; past this many (names made up by a peer) the memory starts again."""
_ENCODED: dict[str, bytes] = {}
_CHECKED: dict[tuple[bytes, re.Pattern | None], str] = {}


def _put_name(parts: list[bytes], text: str) -> None:
    field = _ENCODED.get(text)
    if field is None:
        raw = text.encode()
        if not 0 < len(raw) <= MAX_NAME * 4:
            raise ValueError(f"a name of {len(raw)} bytes")
        if len(_ENCODED) >= NAMES_KEPT:
            _ENCODED.clear()
        field = _ENCODED[text] = _NAME.pack(len(raw)) + raw
    parts.append(field)


def _put_frame(parts: list[bytes], frame: Frame) -> None:
    ack = NO_ACK if frame.ack is None else frame.ack
    parts.append(_FRAME.pack(frame.id, frame.src_addr, frame.dst_addr, frame.size, frame.t0, frame.seq, ack))
    _put_name(parts, frame.src_link)
    _put_name(parts, frame.dst_link)
    _put_name(parts, frame.kind)


def encode_transmission(host: str, epoch_ns: int, number: int, frame: Frame, t: float, duration: float,
                        position: Any, session: str = "0") -> bytes:
    flags = 0
    x = y = z = 0.0
    if position is not None:
        flags |= HAS_POSITION
        x, y, z = (float(c) for c in position)
    if frame.ref is not None:
        flags |= HAS_REF
    app = frame.app_frame
    if isinstance(app, AppFrame):
        flags |= HAS_APP
    parts = [_FIXED.pack(VERSION, flags, epoch_ns, number, t, duration, x, y, z)]
    _put_name(parts, host)
    _put_name(parts, session)
    _put_frame(parts, frame)
    if frame.ref is not None:
        _put_frame(parts, frame.ref)
    if flags & HAS_APP:
        meta = b"" if app.meta is None else json.dumps(app.meta, separators=(",", ":"), default=_jsonable).encode()
        real, payload = bytes(app.real), bytes(app.payload)
        offset = _slice_at(real, payload)
        parts.append(_APP.pack(app.seq, app.src, app.dst, app.t0, len(meta), len(real), len(payload),
                               FOLLOWS if offset < 0 else offset))
        _put_name(parts, app.packet.name)
        parts.append(meta)
        parts.append(real)
        if offset < 0:
            parts.append(payload)
    body = b"".join(parts)
    return body + _CRC.pack(zlib.crc32(body))


def _slice_at(real: bytes, payload: bytes) -> int:
    """Where ``payload`` is in ``real`` (-1: it is not): after the packet's header, a few bytes in
    (looked for there first: a search of a 2 kB payload costs more than the rest of the encoding)."""
    for offset in range(min(16, len(real) - len(payload) + 1)):
        if real.startswith(payload, offset):
            return offset
    return real.find(payload)


def _jsonable(value: Any) -> Any:
    if isinstance(value, (bytes, bytearray)):
        return value.hex()
    return str(value)


def _number(header: dict, key: str, finite: bool = True) -> float:
    value = header.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (finite and not math.isfinite(value)):
        raise NetError(f"{key!r} is not a number")
    return float(value)


def _integer(header: dict, key: str, low: int = -(2**63), high: int = 2**63) -> int:
    value = header.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise NetError(f"{key!r} is not an integer in range")
    return value


def _text(header: dict, key: str) -> str:
    value = header.get(key)
    if not isinstance(value, str) or not 0 < len(value) <= 256:
        raise NetError(f"{key!r} is not a name")
    return value


class _Reader:
    """Reads a transmission's fields in order; every shortfall or nonsense is a :class:`NetError`."""

    __slots__ = ("data", "at", "end")

    def __init__(self, data: bytes, end: int):
        self.data = data
        self.at = 0
        self.end = end  # (the CRC after it is not read as fields)

    def fixed(self, layout: struct.Struct) -> tuple:
        at = self.at
        if at + layout.size > self.end:
            raise NetError("truncated")
        self.at = at + layout.size
        return layout.unpack_from(self.data, at)

    def name(self, what: str, pattern: re.Pattern | None = None) -> str:
        data, at = self.data, self.at + 2
        if at > self.end:
            raise NetError("truncated")
        length = (data[at - 2] << 8) | data[at - 1]
        if not 0 < length <= MAX_NAME * 4 or at + length > self.end:
            raise NetError(f"{what} is not a name")
        self.at = at + length
        raw = data[at:at + length]
        text = _CHECKED.get((raw, pattern))
        if text is not None:
            return text  # (checked already, against the same pattern)
        try:
            text = raw.decode()
        except UnicodeDecodeError:
            raise NetError(f"{what} is not UTF-8") from None
        if len(text) > MAX_NAME:
            raise NetError(f"{what} is too long")
        if pattern is not None and not pattern.fullmatch(text):
            raise NetError(f"{what} is not a name of its kind")
        if len(_CHECKED) >= NAMES_KEPT:
            _CHECKED.clear()
        _CHECKED[(raw, pattern)] = text
        return text

    def take(self, length: int) -> bytes:
        at = self.at
        if at + length > self.end:
            raise NetError("truncated")
        self.at = at + length
        return self.data[at:at + length]

    def frame(self) -> Frame:
        id_, src_addr, dst_addr, size, t0, seq, ack = self.fixed(_FRAME)
        src_link = self.name("the source link", LINK_NAME)
        dst_link = self.name("the destination link", LINK_NAME)
        kind = self.name("the kind", KIND)
        if not (-1 <= src_addr <= 255 and dst_addr <= 255 and size <= 1 << 24 and math.isfinite(t0)):
            raise NetError("a frame's address, size or time is out of range")
        frame = Frame(id_, src_link, dst_link, dst_addr, size, t0, None, None, kind, None, seq)
        frame.src_addr = src_addr
        if ack != NO_ACK:
            if ack > 255:
                raise NetError("ACK retries out of range")
            frame.ack = ack  # retries: the receiving modem answers with an ACK frame
        return frame

    def app_frame(self) -> AppFrame:
        """The application's frame a transmission carries, its payload a slice of its real packet or after it."""
        seq, src, dst, t0, meta_length, real_length, payload_length, offset = self.fixed(_APP)
        if not (-1 <= src <= 255 and dst <= 255 and math.isfinite(t0)):
            raise NetError("an application frame's address or time is out of range")
        if meta_length > MAX_HEADER:
            raise NetError("meta that long")
        packet = _packet(self.name("the packet class", PACKET_NAME))
        meta = None
        if meta_length:
            meta = _loads(self.take(meta_length))
            if not isinstance(meta, dict):
                raise NetError("meta is not an object")
        real = self.take(real_length)
        if offset == FOLLOWS:
            payload = self.take(payload_length)
        elif offset + payload_length <= real_length:
            payload = real[offset:offset + payload_length]
        else:
            raise NetError("a payload beyond its packet")
        return AppFrame(real, payload, packet, seq, src, dst, t0, meta)


@functools.lru_cache(maxsize=64)
def _packet(name: str) -> Any:
    try:
        return packet_class(name)
    except ValueError:
        return Raw()


def _loads(data: bytes) -> Any:
    """JSON from another daemon, bounded: with few brackets it cannot be deep, and is parsed at once
    (the common case, on the hot path); otherwise :mod:`hilgate.core.safejson` checks it first."""
    if data.count(b"{") + data.count(b"[") <= safejson.MAX_DEPTH:
        try:
            return json.loads(data)
        except (UnicodeDecodeError, ValueError) as exc:
            raise NetError(f"not JSON: {exc}") from None
    try:
        return safejson.loads(data, max_bytes=MAX_HEADER)
    except ValueError as exc:
        raise NetError(f"bad JSON: {exc}") from None


def decode_transmission(data: bytes) -> Transmission:
    if len(data) > MAX_TRANSMISSION:
        raise NetError(f"{len(data)} bytes: longer than any transmission")
    if len(data) < _FIXED.size + _CRC.size:
        raise NetError("truncated")
    if data[0] != VERSION:
        raise NetError(f"format {data[0]}, not {VERSION}: another hilgate version")
    if zlib.crc32(memoryview(data)[:-_CRC.size]) != _CRC.unpack_from(data, len(data) - _CRC.size)[0]:
        raise NetError("the CRC does not match: damaged on the way", "damaged")
    reader = _Reader(data, len(data) - _CRC.size)
    _, flags, epoch_ns, number, t, duration, x, y, z = reader.fixed(_FIXED)
    if not (math.isfinite(t) and math.isfinite(duration)):
        raise NetError("a time that is not a number")
    if not 0 <= duration <= MAX_DURATION_S:
        raise NetError(f"a duration of {duration!r} s")
    position = None
    if flags & HAS_POSITION:
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            raise NetError("a position that is not a number")
        position = (x, y, z)
    host = reader.name("the host", LINK_NAME)
    session = reader.name("the session", SESSION)
    frame = reader.frame()
    ref_key = None
    if flags & HAS_REF:
        ref = frame.ref = reader.frame()
        ref_key = (ref.src_link, ref.id)
    if flags & HAS_APP:
        frame.app_frame = reader.app_frame()
    if reader.at != reader.end:
        raise NetError("trailing bytes")
    return Transmission(host, epoch_ns, number, frame, t, duration, position, ref_key, session)


class ReplayWindow:
    """The message numbers of one host's sessions: which were seen, which are new.

    A session is the sender's start (its Zenoh session id and epoch): numbers count from 1 in each, so a
    restarted host is a new session, never a gap.  Within a session, IPsec's anti-replay window (RFC 4303
    §3.4.3) remembers the last :data:`WINDOW` numbers below the highest: a number seen, or older than
    that, is a replay; a number ahead counts the numbers skipped as gaps (what Zenoh dropped), at most
    :data:`MAX_JUMP` at once (a larger jump is refused: numbers are not made up that far ahead).  After
    the host was down, any jump ahead is taken without a gap (numbers went on for the hosts that still
    heard it).

    IPsec's window trusts its highest number and its one session, and so did this one: with a host's
    stolen key, one message of a session a nanosecond newer (or numbered far ahead) moved it, and every
    later frame of the honest host was a replay, even after it restarted.  So here no one message moves
    what the honest host's frames are judged by:

    - **Sessions** are kept side by side (:data:`SESSIONS`, the one heard least lately forgotten first),
      each with its numbers: a forged session beside the host's own costs the host nothing.  A session
      older than the newest heard (by epoch: a start before the latest) is heard only while its daemon
      is alive (``alive``: its Zenoh id holds the host's liveliness token, which only the host's key can
      declare), so a host restarted after a forged session of a later epoch is heard, and the messages
      of a start whose daemon is gone are replays of the past.  A known session's message with another
      epoch is none of it (``bad_message``).
    - **A session first heard** starts at the number heard when it started before this window listened
      (its epoch before ``since_ns``), and so does the first session the window hears at all: this
      daemon was not there for the numbers before (it started, or the host came into its scene, while
      that host ran), and counting them all as a gap was a lie (net_gap by the thousand), past
      :data:`MAX_JUMP` a refusal of every message.  Judged per session, not by the window's first
      message: a forged session heard first leaves the host's own session started at its number.
    - **Runs** of numbers within a session are followed side by side too (:data:`RUNS`): a number up to
      :data:`WINDOW` ahead of a run moves it (Zenoh's gaps); one further ahead starts a run of its own
      instead of moving the honest one, which goes on undisturbed: one forged number costs the host at
      most the frame of its number.  A number below every run's window is a replay.

    Only a message that would be used may move anything: the caller checks everything else first (it
    decodes, its host and link are right, its times and epoch are plausible) and asks here last.  A
    thief who keeps sending can still silence the host (a run or a session for every honest frame): that
    is what revoking the key is for (docs/security.md)."""

    WINDOW = 1024
    MAX_JUMP = 1 << 24
    SESSIONS = 4
    RUNS = 4

    __slots__ = ("sessions", "newest", "resync", "since_ns")

    def __init__(self, since_ns: int = 0) -> None:
        self.sessions: dict[str, _Session] = {}  # (in the order last heard: the first is forgotten first)
        self.newest: int | None = None  # the newest epoch heard: the host's latest start
        self.resync = False
        self.since_ns = since_ns  # (UNIX ns) since when this window hears the host's messages

    def admit(self, session: str, epoch_ns: int, number: int, alive: bool = False) -> str | int:
        """``"replay"``, ``"bad_message"`` (a jump too far, an epoch not its session's), or the count of
        numbers skipped (0: in order).  ``alive``: the session's daemon holds the host's liveliness token."""
        newest = self.newest
        if newest is not None and epoch_ns < newest and not alive:
            return "replay"  # an earlier start of the host, its daemon gone
        sessions = self.sessions
        known = sessions.get(session)
        if known is None:
            if newest is not None and epoch_ns == newest and not alive:
                return "replay"  # a second start beside the newest
            if newest is None or epoch_ns < self.since_ns:  # its numbers before were not for this window
                known, verdict = _Session(epoch_ns, number), 0
            else:
                known, verdict = _Session(epoch_ns), None
        elif known.epoch_ns != epoch_ns:
            return "bad_message"
        else:
            verdict = None
        if verdict is None:
            verdict = known.admit(number, self.resync, self.WINDOW, self.MAX_JUMP, self.RUNS)
        if isinstance(verdict, str):
            return verdict  # (a session only refused is not remembered: it takes no honest one's place)
        sessions.pop(session, None)
        if len(sessions) >= self.SESSIONS:
            del sessions[next(iter(sessions))]
        sessions[session] = known
        self.resync = False
        if newest is None or epoch_ns > newest:
            self.newest = epoch_ns
        return verdict


class _Session:
    """One session's runs of numbers, each ``[highest, seen]`` (bit i of ``seen``: number highest - i was
    heard), the one moved last at the end.  A session starts with a run at 0 (numbers count from 1), or
    at the number first heard when the window was not there for those before (``first``)."""

    __slots__ = ("epoch_ns", "runs")

    def __init__(self, epoch_ns: int, first: int = 0):
        self.epoch_ns = epoch_ns
        self.runs: list[list[int]] = [[first, 1]]

    def admit(self, number: int, resync: bool, window: int, max_jump: int, most: int) -> str | int:
        runs = self.runs
        below = None  # the run whose highest is the largest below the number
        for run in runs:
            back = run[0] - number
            if 0 <= back < window:
                if (run[1] >> back) & 1:
                    return "replay"
                run[1] |= 1 << back  # late but never seen (counted as a gap when it was skipped)
                runs.remove(run)
                runs.append(run)
                return 0
            if back < 0 and (below is None or run[0] > below[0]):
                below = run
        if below is None:
            return "replay"  # older than every run's window
        skipped = number - below[0] - 1
        if resync:
            skipped = 0
        elif skipped >= max_jump:
            return "bad_message"
        runs.remove(below)
        if number - below[0] <= window:
            shift = number - below[0]
            below[0], below[1] = number, ((below[1] << shift) | 1) & ((1 << window) - 1)
            runs.append(below)
        else:  # far ahead: a run of its own; the run below goes on as it was
            runs.append(below)
            if len(runs) >= most:
                del runs[0]
            runs.append([number, 1])
        return skipped


def encode_pose(host: str, epoch_ns: int, vehicle: str, t: float, position: Any, velocity: Any) -> bytes:
    return json.dumps({"h": host, "e": epoch_ns, "v": vehicle, "t": t,
                       "p": None if position is None else [float(c) for c in position],
                       "u": None if velocity is None else [float(c) for c in velocity]},
                      separators=(",", ":")).encode()


def decode_pose(data: bytes) -> dict[str, Any]:
    if len(data) > MAX_HEADER:
        raise NetError("a pose that long")
    message = _loads(data)
    if not isinstance(message, dict):
        raise NetError("a pose is an object")
    result = {"host": _text(message, "h"), "epoch_ns": _integer(message, "e"), "vehicle": _text(message, "v"),
              "t": _number(message, "t")}
    if not LINK_NAME.fullmatch(result["host"]):
        raise NetError("a host that is not a name")
    for key, name in (("p", "position"), ("u", "velocity")):
        value = message.get(key)
        if value is not None and not (isinstance(value, list) and len(value) == 3 and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in value)):
            raise NetError(f"{key!r} is not [x, y, z]")
        result[name] = None if value is None else tuple(float(c) for c in value)
    return result

