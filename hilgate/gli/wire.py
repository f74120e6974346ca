"""hilgate's GLI framing for stream sockets (Unix and TCP), as a codec without I/O.

Every message is::

    u32 length (big-endian; counts the type byte and the body) | u8 type | body

==========  ===================  =====================================================================
type        direction            body
==========  ===================  =====================================================================
1 HELLO     client → hilgate     UTF-8 JSON ``{"link": "<id>"}``; optional on a link's own Unix
                                 socket; on TCP the first message, answering CHALLENGE with
                                 ``{"link": "<id>", "proof": "<hex>"}`` (:mod:`hilgate.gli.token`)
2 WELCOME   hilgate → client     UTF-8 JSON ``{"link", "address", "packet", "max_payload", "version"}``
3 SEND      client → hilgate     ``u8 dst`` (255 = broadcast) then the payload
4 RECV      hilgate → client     ``u8 src | u8 dst | f64 model time of delivery (big-endian)`` then
                                 the payload
5 STATE     hilgate → client     ``u8``: 1 READY, 0 BUSY (the link's transmit FIFO is empty or not)
6 ERROR     hilgate → client     UTF-8 JSON ``{"error": "..."}``
7 COMMAND   client → hilgate     UTF-8 JSON, a request for the link's vehicle (see hilgate.client)
8 REPLY     hilgate → client     UTF-8 JSON answer to a COMMAND
9 CHALLENGE hilgate → client     TCP only, sent on connecting: UTF-8 JSON ``{"nonce": "<64 hex>"}``;
                                 HELLO's ``proof`` is HMAC-SHA256(token, the nonce's 32 bytes) in hex
==========  ===================  =====================================================================

Addresses are 8 bits (version 1).  Simulated links with wider addresses (up to 65534, ``hilgate sim``
only) are refused by ``hilgate run`` before any endpoint opens, so this framing never has to carry
one; widening it would need a new ``version`` with ``u16`` fields announced in WELCOME, leaving
version-1 clients as they are.

Payloads are the application's bytes only; hilgate wraps them in the link's packet class, so their
size on air is what a dccomms application of the same class would have sent.
"""

from __future__ import annotations

import json
import struct
from typing import Any

from ..core import safejson

HELLO, WELCOME, SEND, RECV, STATE, ERROR, COMMAND, REPLY, CHALLENGE = range(1, 10)
MAX_MESSAGE = 65536
VERSION = 1
_HEADER = struct.Struct(">IB")
_RECV = struct.Struct(">BBd")


class WireError(ValueError):
    """The peer broke the framing; the connection cannot continue."""


def encode(kind: int, body: bytes = b"") -> bytes:
    if len(body) + 1 > MAX_MESSAGE:
        raise WireError(f"message of {len(body) + 1} bytes exceeds {MAX_MESSAGE}")
    return _HEADER.pack(len(body) + 1, kind) + body


def encode_json(kind: int, obj: Any) -> bytes:
    return encode(kind, json.dumps(obj, separators=(",", ":")).encode())


def encode_send(dst: int, payload: bytes) -> bytes:
    return encode(SEND, bytes([dst & 0xFF]) + payload)


def encode_recv(src: int, dst: int, t: float, payload: bytes) -> bytes:
    return encode(RECV, _RECV.pack(src & 0xFF, dst & 0xFF, t) + payload)


def encode_state(ready: bool) -> bytes:
    return encode(STATE, b"\x01" if ready else b"\x00")


def decode_send(body: bytes) -> tuple[int, bytes]:
    if len(body) < 1:
        raise WireError("SEND needs a destination byte")
    return body[0], bytes(body[1:])


def decode_recv(body: bytes) -> tuple[int, int, float, bytes]:
    if len(body) < _RECV.size:
        raise WireError("RECV too short")
    src, dst, t = _RECV.unpack_from(body)
    return src, dst, t, bytes(body[_RECV.size:])


def decode_json(body: bytes) -> Any:
    """A JSON body, bounded in depth (a 5 000-deep HELLO is refused, not a RecursionError)."""
    try:
        return safejson.loads(body, max_bytes=MAX_MESSAGE)
    except safejson.JsonError as exc:
        raise WireError(f"bad JSON: {exc}") from None


class Decoder:
    """Feed bytes as they come; take whole ``(type, body)`` messages out."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        buffer = self._buffer
        buffer += data
        messages = []
        while len(buffer) >= _HEADER.size:
            length, kind = _HEADER.unpack_from(buffer)
            if length < 1 or length > MAX_MESSAGE:
                raise WireError(f"bad message length {length}")
            end = 4 + length
            if len(buffer) < end:
                break
            messages.append((kind, bytes(buffer[_HEADER.size:end])))
            del buffer[:end]
        return messages

    @property
    def pending(self) -> int:
        """Bytes of an incomplete message (a client that vanishes mid-frame leaves some)."""
        return len(self._buffer)
