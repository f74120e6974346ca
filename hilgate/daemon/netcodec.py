"""What daemons tell each other over Zenoh, as bytes: transmissions, poses, host announcements.  No I/O.

A **transmission** is one frame going on air on the sender's host: enough for every other host's
medium to hand out its arrivals exactly as the sender's own medium does (frame, start, duration,
the sender's position at the start) and for the receiving applications to get the frame back
(the application's packet and what the receiving modem needs to print it)::

    u32 header length (big-endian) | header (UTF-8 JSON) | real packet | payload

Header keys: ``h`` sending host, ``e`` its epoch (ns of the UNIX clock at its model time 0), ``n`` the
host's message counter (gaps are frames Zenoh dropped), ``l`` sending link, ``i`` frame id, ``dl``/``da``
destination link and address, ``sa`` source address, ``s`` size on air, ``t`` start (the sender's model
time), ``d`` duration, ``k`` kind (``data``, ``rts``, ``cts``, ``ack``), ``p`` the sender's position at
``t`` (or null), ``ak`` the retries of a frame its receiver acknowledges (null: none), ``r`` the frame a
control frame or an acoustic ACK serves (same keys, one level), ``a`` the application
frame (``c`` packet class, ``q`` seq, ``s`` src, ``d`` dst, ``t`` t0, ``m`` meta, ``rl`` real length).

A **pose** is UTF-8 JSON ``{"h", "e", "v" vehicle, "t" measured (sender's model time), "p" [x, y, z],
"u" velocity or null}``.  Model times convert between hosts through the epochs:
``t_here = t_there + (e_there − e_here)·1e-9`` (the daemons run at the same speed, 1).
"""

from __future__ import annotations

import functools
import json
import math
import struct
from dataclasses import dataclass
from typing import Any

from ..core import safejson
from ..core.backend import AppFrame
from ..core.packets import Raw, packet_class
from ..models.frame import Frame

__all__ = ["Transmission", "encode_transmission", "decode_transmission", "encode_pose", "decode_pose",
           "NetError", "to_local"]

_LENGTH = struct.Struct(">I")
MAX_HEADER = 16384
MAX_DURATION_S = 3600.0  # a frame longer on air than this is not one a modem sends


class NetError(ValueError):
    """A message from another host that cannot be read (counted, never raised into the loop)."""


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


def to_local(t_there: float, epoch_there_ns: int, epoch_here_ns: int) -> float:
    """A model time of another host as this host's model time (both at speed 1)."""
    return t_there + (epoch_there_ns - epoch_here_ns) * 1e-9


def _frame_fields(frame: Frame) -> dict[str, Any]:
    return {"l": frame.src_link, "i": frame.id, "dl": frame.dst_link, "da": frame.dst_addr, "sa": frame.src_addr,
            "s": frame.size, "k": frame.kind, "q": frame.seq, "t0": frame.t0, "ak": frame.ack}


def encode_transmission(host: str, epoch_ns: int, number: int, frame: Frame, t: float, duration: float,
                        position: Any) -> bytes:
    header = _frame_fields(frame)
    header.update(h=host, e=epoch_ns, n=number, t=t, d=duration,
                  p=None if position is None else [float(c) for c in position])
    if frame.ref is not None:
        header["r"] = _frame_fields(frame.ref)
    real = payload = b""
    app = frame.app_frame
    if isinstance(app, AppFrame):
        real, payload = bytes(app.real), bytes(app.payload)
        header["a"] = {"c": app.packet.name, "q": app.seq, "s": app.src, "d": app.dst, "t": app.t0,
                       "m": app.meta, "rl": len(real)}
    blob = json.dumps(header, separators=(",", ":"), default=_jsonable).encode()
    return _LENGTH.pack(len(blob)) + blob + real + payload


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


def _frame(fields: dict) -> Frame:
    if not isinstance(fields, dict):
        raise NetError("a frame is an object")
    frame = Frame(_integer(fields, "i"), _text(fields, "l"), _text(fields, "dl"), _integer(fields, "da", 0, 255),
                  _integer(fields, "s", 0, 1 << 24), _number(fields, "t0"), None, None,
                  _text(fields, "k"), None, _integer(fields, "q"))
    frame.src_addr = _integer(fields, "sa", -1, 255)
    if fields.get("ak") is not None:
        frame.ack = _integer(fields, "ak", 0, 255)  # retries: the receiving modem answers with an ACK frame
    return frame


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
    if len(data) < _LENGTH.size:
        raise NetError("too short")
    (length,) = _LENGTH.unpack_from(data)
    if length > MAX_HEADER or _LENGTH.size + length > len(data):
        raise NetError("bad header length")
    header = _loads(data[_LENGTH.size:_LENGTH.size + length])
    if not isinstance(header, dict):
        raise NetError("the header is not an object")
    frame = _frame(header)
    ref_key = None
    if header.get("r") is not None:
        ref = _frame(header["r"])
        frame.ref = ref
        ref_key = (ref.src_link, ref.id)
    body = data[_LENGTH.size + length:]
    app = header.get("a")
    if app is not None:
        if not isinstance(app, dict):
            raise NetError("'a' is not an object")
        real_length = _integer(app, "rl", 0, len(body))
        packet = _packet(_text(app, "c"))
        meta = app.get("m")
        if meta is not None and not isinstance(meta, dict):
            raise NetError("'m' is not an object")
        frame.app_frame = AppFrame(body[:real_length], body[real_length:], packet, _integer(app, "q"),
                                   _integer(app, "s", -1, 255), _integer(app, "d", 0, 255), _number(app, "t"), meta)
    position = header.get("p")
    if position is not None:
        if not (isinstance(position, list) and len(position) == 3 and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in position)):
            raise NetError("'p' is not [x, y, z]")
        position = (float(position[0]), float(position[1]), float(position[2]))
    duration = _number(header, "d")
    if not 0 <= duration <= MAX_DURATION_S:
        raise NetError(f"a duration of {duration!r} s")
    return Transmission(_text(header, "h"), _integer(header, "e"), _integer(header, "n"), frame,
                        _number(header, "t"), duration, position, ref_key)


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
    for key, name in (("p", "position"), ("u", "velocity")):
        value = message.get(key)
        if value is not None and not (isinstance(value, list) and len(value) == 3 and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in value)):
            raise NetError(f"{key!r} is not [x, y, z]")
        result[name] = None if value is None else tuple(float(c) for c in value)
    return result

