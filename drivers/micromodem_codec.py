"""WHOI Micro-Modem NMEA-0183 interface, without I/O, and the modem's packet rates.

A sentence is ``$`` + talker and type (``CC…`` from the host, ``CA…``/``SN…`` from the modem) +
``,``-separated fields + ``*hh`` (the XOR of every byte between ``$`` and ``*``, two upper-case hex
digits) + CR LF; a host may leave the checksum out.  Data travel as hex in ``$CCTXD``/``$CARXD``, so a
sentence is text (at most :data:`MAX_LINE` bytes: a 256-byte frame is 512 hex digits).

One codec per side, as h11: :class:`ModemCodec` turns a host's bytes into :class:`Sentence` events
(talker ``CC``), :class:`HostCodec` the modem's (talkers ``CA``, ``SN``, ``UP``); what is no sentence, has
a bad checksum or another talker is a :class:`BadSentence` with why, and the codec goes on.
:func:`sentence` builds one with its checksum.

:data:`RATES` is the modem's packet table: frames per packet and bytes per frame are those of WHOI's
software interface guide, as the ``acomms`` library's rate table gives them (rate 0 FH-FSK 1 × 32,
1 and 2: 3 × 64, 3 and 4: 2 × 256, 5: 8 × 256, 6: 6 × 32).  Burst rates: 80 bit/s for FH-FSK and
about 5400 bit/s for rate 5 (WHOI's Micro-Modem page: "80-5400 bps"), 490 bit/s for rate 6 (the same
page's table, with 2.95 s of packet and 0.3 s of probe and gap before it); rates 1 to 4 are not in a
public figure hilgate could read: they are estimated from rate 5's channel rate (5400 × 14/9 ≈ 8400
bit/s before its Hamming 14:9 code) and each rate's own code as the guide names it (BCH 128:8 → 525,
DSS 1/15 → 560, DSS 1/7 → 1200, BCH 64:10 → 1312 bit/s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

MAX_LINE = 1024
PROBE_S = 0.3
"""Probe and gap before a PSK packet (WHOI's table: signal length − packet length for rate 6)."""


@dataclass(frozen=True)
class Rate:
    frames: int
    frame_bytes: int
    bitrate_bps: float
    psk: bool = True

    @property
    def packet_bytes(self) -> int:
        return self.frames * self.frame_bytes

    def airtime(self, frames: int) -> float:
        """Seconds on air of a packet of ``frames`` full frames (the modem sends whole frames)."""
        return (PROBE_S if self.psk else 0.0) + frames * self.frame_bytes * 8 / self.bitrate_bps


RATES = {
    0: Rate(1, 32, 80.0, psk=False),
    1: Rate(3, 64, 525.0),
    2: Rate(3, 64, 560.0),
    3: Rate(2, 256, 1200.0),
    4: Rate(2, 256, 1312.0),
    5: Rate(8, 256, 5400.0),
    6: Rate(6, 32, 490.0),
}
CI_AIRTIME_S = 32 * 8 / 80.0 / 4
"""An FSK cycle-init minipacket before a rate-0 packet (hilgate's estimate: a quarter of an FSK frame)."""
MINIPACKET_S = 0.5
"""An FSK minipacket: a ping, a ping's reply, an acknowledgement (hilgate's estimate)."""


def checksum(body: str) -> str:
    value = 0
    for byte in body.encode("latin-1"):
        value ^= byte
    return f"{value:02X}"


def sentence(kind: str, *fields: object) -> bytes:
    """``$<kind>,<fields>*hh`` and CR LF."""
    body = ",".join([kind, *(str(f) for f in fields)])
    return f"${body}*{checksum(body)}\r\n".encode("latin-1")


def hhmmss(seconds: float) -> str:
    """The time field of CADRQ/CAERR: hours, minutes, seconds of the day."""
    s = int(seconds) % 86400
    return f"{s // 3600:02d}{s % 3600 // 60:02d}{s % 60:02d}"


@dataclass(frozen=True)
class Sentence:
    kind: str                      # talker and type: CCCYC, CADRQ…
    fields: tuple[str, ...] = ()
    checked: bool = False

    def field(self, index: int) -> str | None:
        return self.fields[index] if index < len(self.fields) else None

    def number(self, index: int) -> int | None:
        text = self.field(index)
        if text is None:
            return None
        text = text.strip()
        return int(text) if text.isdigit() else None


@dataclass(frozen=True)
class BadSentence:
    """Bytes that are no sentence this side takes: ``no sentence``, ``too long``, ``checksum``,
    ``not text``, ``talker``."""

    reason: str
    data: bytes = b""


@dataclass
class _Codec:
    talkers: tuple[str, ...]
    buffer: bytearray = field(default_factory=bytearray)

    def receive_data(self, data: bytes) -> list[object]:
        self.buffer += data
        events: list[object] = []
        while True:
            end = self.buffer.find(b"\n")
            if end < 0:
                if len(self.buffer) > MAX_LINE:
                    events.append(BadSentence("too long", bytes(self.buffer[:64])))
                    self.buffer.clear()
                return events
            line = bytes(self.buffer[:end]).rstrip(b"\r")
            del self.buffer[:end + 1]
            if line:
                events.append(self._parse(line))

    def _parse(self, line: bytes) -> object:
        if len(line) > MAX_LINE:
            return BadSentence("too long", line[:64])
        start = line.find(b"$")
        if start < 0:
            return BadSentence("no sentence", line)
        try:
            text = line[start + 1:].decode("ascii")
        except UnicodeDecodeError:
            return BadSentence("not text", line)
        if any(ord(c) < 32 for c in text):
            return BadSentence("not text", line)
        checked = False
        star = text.rfind("*")
        if star >= 0:
            body, given = text[:star], text[star + 1:].strip()
            if given.upper() != checksum(body):
                return BadSentence("checksum", line)
            checked = True
        else:
            body = text
        parts = body.split(",")
        kind = parts[0].strip().upper()
        if len(kind) < 5 or not kind.isalnum() or not kind.startswith(self.talkers):
            return BadSentence("talker", line)
        return Sentence(kind, tuple(p.strip() for p in parts[1:]), checked)


class ModemCodec(_Codec):
    """The modem's side: a host's sentences (``$CC…``)."""

    def __init__(self) -> None:
        super().__init__(("CC",))


class HostCodec(_Codec):
    """The host's side: the modem's sentences (``$CA…``, ``$SN…``, ``$UP…``)."""

    def __init__(self) -> None:
        super().__init__(("CA", "SN", "UP"))
