"""dccomms packet classes: the bytes of a GLI frame, on the POSIX queues and on air.

A dccomms application puts the *whole fixed buffer* of its packet object on the queue: the real
packet (preamble, header, payload, CRC) padded to the class's maximum size, then a 12-byte *virtual
area* (seq, src, dst as little-endian uint32) at offset max-real-size.  The receiver rebuilds the
packet with its own builder, so both ends must use the same class.  See
``shared/protocols/gli-dccomms.md`` section 2; every size here was checked there against the real
C++ programs (VariableLength2BPacket: 2066-byte messages).

Each class is a small codec without I/O: ``decode_body`` checks a queue body and returns what it
carries, ``encode_body`` builds one; ``encode`` builds the real packet alone (what goes on air).
"""

from __future__ import annotations

import binascii
import re
import struct
from abc import ABC, abstractmethod
from typing import NamedTuple

import fastcrc

VIRTUAL_AREA = 12
_VIRTUAL = struct.Struct("<III")  # seq, src, dst: compiled once, every frame on a queue has it
_ZEROS = memoryview(bytes(8192))  # padding slices of it are not copied before the frame is joined
PREAMBLE = 0x55
from ..models.frame import BROADCAST  # the one broadcast address, as the medium knows it
MAX_QUEUE_MESSAGE = 8192


class PacketError(ValueError):
    """A frame that cannot be accepted; ``reason`` is short and goes into the trace (crc, size, …)."""

    def __init__(self, reason: str, detail: str):
        self.reason = reason
        super().__init__(f"{reason}: {detail}")


def crc16(data: bytes) -> int:
    """CRC-16/XMODEM (poly 0x1021, init 0): binascii's CRC-CCITT with a zero start."""
    return binascii.crc_hqx(data, 0)


def crc32(data: bytes) -> int:
    """dccomms' ``Checksum::crc32``: poly 0x04C11DB7, init 0, MSB first, no final XOR (check value
    0x89A1897F).  That is CRC-32/CKSUM without its final inversion."""
    return fastcrc.crc32.cksum(data) ^ 0xFFFFFFFF


class Decoded(NamedTuple):
    """What a GLI frame carries. ``real`` is the real packet (what goes on air).  A named tuple, not a
    frozen dataclass: one is made per frame, and it is made in a third of the time."""

    real: bytes
    payload: bytes
    seq: int
    src: int
    dst: int


def _address(value: int) -> int:
    return BROADCAST if value >= BROADCAST else value


class PacketClass(ABC):
    name = "?"
    max_real = 0
    max_payload = 0
    addresses_on_air = False
    """Whether the real packet carries its destination (DataLinkFrame does); the others keep it only
    in the virtual area, so a real modem of that class cannot filter by it."""

    @property
    def body_size(self) -> int:
        return self.max_real + VIRTUAL_AREA

    @abstractmethod
    def encode(self, payload: bytes, src: int, dst: int) -> bytes:
        """The real packet carrying ``payload`` (what goes on air)."""

    @abstractmethod
    def parse_real(self, data: bytes) -> tuple[bytes, bytes, int | None, int | None]:
        """Check a real packet at the start of ``data``: (real bytes, payload, src, dst); src/dst are
        None when the class keeps them in the virtual area."""

    @abstractmethod
    def real_length(self, payload_length: int) -> int:
        """Bytes on air for a payload of this length."""

    @abstractmethod
    def frame_length(self, data: bytes) -> int | None:
        """How long the frame starting at ``data`` is, from its header (for hunting frames in a byte
        stream); None if the header is not complete yet.  PacketError if it cannot be a frame."""

    preamble = b"\x55"

    def decode_body(self, body: bytes) -> Decoded:
        max_real = self.max_real
        if len(body) != max_real + VIRTUAL_AREA:
            raise PacketError("size", f"{self.name} frames are {self.body_size} bytes on the queue, got {len(body)}")
        real, payload, src, dst = self.parse_real(body[:max_real])
        seq, v_src, v_dst = _VIRTUAL.unpack_from(body, max_real)
        if src is None:  # (the virtual area's addresses, 255 and above meaning broadcast: _address inline)
            src = BROADCAST if v_src >= BROADCAST else v_src
        if dst is None:
            dst = BROADCAST if v_dst >= BROADCAST else v_dst
        return Decoded(real, payload, seq, src, dst)

    def encode_body(self, real: bytes, seq: int, src: int, dst: int, prefix: bytes = b"") -> bytes:
        """``prefix`` (a queue message's type byte), the real packet padded to the class's fixed size,
        the virtual area: joined in one allocation (a vl2b frame is 2 kB, mostly padding)."""
        return b"".join((prefix, real, _ZEROS[: max(0, self.max_real - len(real))],
                         _VIRTUAL.pack(seq & 0xFFFFFFFF, src & 0xFFFFFFFF, dst & 0xFFFFFFFF)))

    def fit_payload(self, payload: bytes) -> bytes:
        if len(payload) > self.max_payload:
            raise PacketError("size", f"{len(payload)} bytes do not fit a {self.name} payload (max {self.max_payload})")
        return payload


class VariableLength(PacketClass):
    """``55 | len | payload | CRC16(payload)``; len is one byte (vl1b) or two, big-endian (vl2b)."""

    def __init__(self, length_bytes: int):
        self.length_bytes = length_bytes
        self.name = "vl1b" if length_bytes == 1 else "vl2b"
        self.max_payload = 255 if length_bytes == 1 else 2048
        self.max_real = 1 + length_bytes + self.max_payload + 2

    def real_length(self, payload_length: int) -> int:
        return 1 + self.length_bytes + payload_length + 2

    def encode(self, payload: bytes, src: int = 0, dst: int = BROADCAST) -> bytes:
        payload = self.fit_payload(payload)
        length = len(payload).to_bytes(self.length_bytes, "big")
        return bytes([PREAMBLE]) + length + payload + crc16(payload).to_bytes(2, "big")

    def frame_length(self, data: bytes) -> int | None:
        if len(data) < 1 + self.length_bytes:
            return None
        if data[0] != PREAMBLE:
            raise PacketError("preamble", f"{self.name} starts with 0x55")
        length = int.from_bytes(data[1 : 1 + self.length_bytes], "big")
        if length > self.max_payload:
            raise PacketError("length", f"{self.name} payload length {length} > {self.max_payload}")
        return self.real_length(length)

    def parse_real(self, data: bytes):
        if len(data) < 1 + self.length_bytes + 2 or data[0] != PREAMBLE:
            raise PacketError("preamble", f"{self.name} starts with 0x55")
        length = int.from_bytes(data[1 : 1 + self.length_bytes], "big")
        if length > self.max_payload:
            raise PacketError("length", f"{self.name} payload length {length} > {self.max_payload}")
        start = 1 + self.length_bytes
        end = start + length
        if len(data) < end + 2:
            raise PacketError("length", f"{self.name} frame truncated")
        payload = bytes(data[start:end])
        if binascii.crc_hqx(data[start : end + 2], 0) != 0:  # (crc16 written out: every queued frame passes here)
            raise PacketError("crc", f"{self.name} CRC-16 mismatch")
        return bytes(data[: end + 2]), payload, None, None


class DataLinkFrame(PacketClass):
    """``55 55 | dst | src | len u16 BE | payload | FCS`` with the FCS over dst..payload."""

    addresses_on_air = True

    def __init__(self, fcs_bytes: int):
        self.fcs_bytes = fcs_bytes
        self.name = "dlf16" if fcs_bytes == 2 else "dlf32"
        self.max_payload = 2048
        self.max_real = 6 + self.max_payload + fcs_bytes
        self._crc = crc16 if fcs_bytes == 2 else crc32

    def real_length(self, payload_length: int) -> int:
        return 6 + payload_length + self.fcs_bytes

    def encode(self, payload: bytes, src: int = 0, dst: int = BROADCAST) -> bytes:
        payload = self.fit_payload(payload)
        covered = bytes([dst & 0xFF, src & 0xFF]) + len(payload).to_bytes(2, "big") + payload
        return b"\x55\x55" + covered + self._crc(covered).to_bytes(self.fcs_bytes, "big")

    preamble = b"\x55\x55"

    def frame_length(self, data: bytes) -> int | None:
        if len(data) < 6:
            return None
        if data[0] != PREAMBLE or data[1] != PREAMBLE:
            raise PacketError("preamble", f"{self.name} starts with 0x55 0x55")
        length = int.from_bytes(data[4:6], "big")
        if length > self.max_payload:
            raise PacketError("length", f"{self.name} payload length {length} > {self.max_payload}")
        return self.real_length(length)

    def parse_real(self, data: bytes):
        if len(data) < 6 + self.fcs_bytes or data[0] != PREAMBLE or data[1] != PREAMBLE:
            raise PacketError("preamble", f"{self.name} starts with 0x55 0x55")
        length = int.from_bytes(data[4:6], "big")
        if length > self.max_payload:
            raise PacketError("length", f"{self.name} payload length {length} > {self.max_payload}")
        end = 6 + length
        if len(data) < end + self.fcs_bytes:
            raise PacketError("length", f"{self.name} frame truncated")
        if self._crc(bytes(data[2 : end + self.fcs_bytes])) != 0:
            raise PacketError("crc", f"{self.name} FCS mismatch")
        return bytes(data[: end + self.fcs_bytes]), bytes(data[6:end]), data[3], data[2]


class SimplePacket(PacketClass):
    """``55 | payload | CRC16(payload)``, N bytes in all (dccomms' SimplePacket(20): 17 bytes of
    payload, the first two a big-endian sequence number by convention); no addresses, they travel
    in the virtual area.  Checked against dccomms' S100 bridge: ``55 41..51 A6 72``."""

    def __init__(self, size: int):
        if size < 4:
            raise ValueError("a SimplePacket needs at least 4 bytes (preamble, payload, CRC-16)")
        self.name = f"simple:{size}"
        self.max_payload = size - 3
        self.max_real = size

    def real_length(self, payload_length: int) -> int:
        return self.max_real

    def fit_payload(self, payload: bytes) -> bytes:
        return super().fit_payload(payload).ljust(self.max_payload, b"\0")

    def encode(self, payload: bytes, src: int = 0, dst: int = BROADCAST) -> bytes:
        payload = self.fit_payload(payload)
        return bytes([PREAMBLE]) + payload + crc16(payload).to_bytes(2, "big")

    def frame_length(self, data: bytes) -> int | None:
        if not data:
            return None
        if data[0] != PREAMBLE:
            raise PacketError("preamble", f"{self.name} starts with 0x55")
        return self.max_real

    def parse_real(self, data: bytes):
        if len(data) < self.max_real or data[0] != PREAMBLE:
            raise PacketError("preamble", f"{self.name} starts with 0x55")
        if crc16(bytes(data[1 : self.max_real])) != 0:
            raise PacketError("crc", f"{self.name} CRC-16 mismatch")
        return bytes(data[: self.max_real]), bytes(data[1 : self.max_real - 2]), None, None


class Raw(PacketClass):
    """hilgate's own: the queue body is the frame's bytes followed by the 12-byte virtual area; no
    preamble and no CRC, and the size on air is the number of bytes."""

    name = "raw"
    max_payload = MAX_QUEUE_MESSAGE - 1 - VIRTUAL_AREA
    max_real = max_payload

    def real_length(self, payload_length: int) -> int:
        return payload_length

    def encode(self, payload: bytes, src: int = 0, dst: int = BROADCAST) -> bytes:
        return self.fit_payload(payload)

    preamble = b""

    def frame_length(self, data: bytes) -> int | None:
        raise PacketError("framing", "raw frames have no framing of their own (see HilgateFrame)")

    def parse_real(self, data: bytes):
        return bytes(data), bytes(data), None, None

    def decode_body(self, body: bytes) -> Decoded:
        if len(body) < VIRTUAL_AREA:
            raise PacketError("size", f"raw frames end with the {VIRTUAL_AREA}-byte virtual area, got {len(body)} bytes")
        real = bytes(body[:-VIRTUAL_AREA])
        seq, src, dst = _VIRTUAL.unpack_from(body, len(body) - VIRTUAL_AREA)
        return Decoded(real, real, seq, _address(src), _address(dst))

    def encode_body(self, real: bytes, seq: int, src: int, dst: int, prefix: bytes = b"") -> bytes:
        return b"".join((prefix, real, _VIRTUAL.pack(seq & 0xFFFFFFFF, src & 0xFFFFFFFF, dst & 0xFFFFFFFF)))


class HilgateFrame(VariableLength):
    """hilgate's own framing for ``raw`` links on byte-stream modems (S100): ``A5 5A | len u16 BE |
    payload | CRC16(len..payload)``.  Raw payloads have no preamble or CRC, so on a serial line they
    get this one; the size on air grows by 6 bytes."""

    preamble = b"\xa5\x5a"

    def __init__(self) -> None:
        super().__init__(2)
        self.name = "hilgate-frame"
        self.max_payload = 4096
        self.max_real = 2 + 2 + self.max_payload + 2

    def real_length(self, payload_length: int) -> int:
        return 4 + payload_length + 2

    def encode(self, payload: bytes, src: int = 0, dst: int = BROADCAST) -> bytes:
        payload = self.fit_payload(payload)
        covered = len(payload).to_bytes(2, "big") + payload
        return self.preamble + covered + crc16(covered).to_bytes(2, "big")

    def frame_length(self, data: bytes) -> int | None:
        if len(data) < 4:
            return None
        if bytes(data[:2]) != self.preamble:
            raise PacketError("preamble", "hilgate frames start with A5 5A")
        length = int.from_bytes(data[2:4], "big")
        if length > self.max_payload:
            raise PacketError("length", f"hilgate frame length {length} > {self.max_payload}")
        return self.real_length(length)

    def parse_real(self, data: bytes):
        total = self.frame_length(data)
        if total is None or len(data) < total:
            raise PacketError("length", "hilgate frame truncated")
        if crc16(bytes(data[2:total])) != 0:
            raise PacketError("crc", "hilgate frame CRC-16 mismatch")
        return bytes(data[:total]), bytes(data[4 : total - 2]), None, None


def packet_class(name: str) -> PacketClass:
    if name == "vl1b":
        return VariableLength(1)
    if name == "vl2b":
        return VariableLength(2)
    if name == "dlf16":
        return DataLinkFrame(2)
    if name == "dlf32":
        return DataLinkFrame(4)
    if name == "raw":
        return Raw()
    match = re.fullmatch(r"simple:(\d+)", name)
    if match:
        return SimplePacket(int(match.group(1)))
    raise ValueError(f"unknown packet class {name!r}")
