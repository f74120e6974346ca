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
1 and 2: 3 × 64, 3 and 4: 2 × 256, 5: 8 × 256, 6: 6 × 32).  The bit rate of each is WHOI's own name
for it, in the public ``libumutil.h`` of its Micro-Modem utilities (``TXR_80_FSK``, ``TXR_250_SPRD``,
``TXR_500_SPRD``, ``TXR_1200_SPRD``, ``TXR_1300_RBC``, ``TXR_5300_RBC``: 80, 250, 500, 1200, 1300 and
5300 bit/s for rates 0 to 5), and 490 bit/s for rate 6 (WHOI's Micro-Modem page, whose table gives
rate 6 2.95 s of packet and 3.25 s of signal: 0.3 s of probe and gap before a PSK packet).  Those
rates are the burst rates, user bytes over the packet's time, so a packet lasts its bytes at that rate
(and, PSK, the probe before it).  (They were estimates before: 525 bit/s for rate 1 from rate 5's
channel rate, half a rate-1 packet's real time.)

:func:`cst` formats the receive statistics ``$CACST`` as a Micro-Modem 2 prints its version 8: the
fields of ``acomms``' parser, zero-padded as a public capture shows them (``$CACST,8,0,
20250606230123.348554,06,32767,45,0102,0123,07,00,00,00,00,1,001,000,0,5,1,0,150,26.0,9.48,-100,
-6.48,-01,0.01,51,25000,5000,0,-1,-1,00*4A``) and as ``libumutil.h``'s example does (``…,0318,0193,10,
00,00,01,01,2,004,004,…``).
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
    0: Rate(1, 32, 80.0, psk=False),  # TXR_80_FSK     (libumutil.h)
    1: Rate(3, 64, 250.0),            # TXR_250_SPRD   (libumutil.h)
    2: Rate(3, 64, 500.0),            # TXR_500_SPRD   (libumutil.h)
    3: Rate(2, 256, 1200.0),          # TXR_1200_SPRD  (libumutil.h)
    4: Rate(2, 256, 1300.0),          # TXR_1300_RBC   (libumutil.h)
    5: Rate(8, 256, 5300.0),          # TXR_5300_RBC   (libumutil.h)
    6: Rate(6, 32, 490.0),            # WHOI's Micro-Modem page, "PSK Rate 6 | 490"
}
RATE_SOURCES = {0: "libumutil.h TXR_80_FSK", 1: "libumutil.h TXR_250_SPRD", 2: "libumutil.h TXR_500_SPRD",
                3: "libumutil.h TXR_1200_SPRD", 4: "libumutil.h TXR_1300_RBC", 5: "libumutil.h TXR_5300_RBC",
                6: "WHOI's Micro-Modem page (rate 6: 490 bps, 2.95 s packet, 3.25 s signal)"}
"""Where each rate's bit rate comes from (docs/conformance-micromodem.md prints the table from these)."""
CI_AIRTIME_S = 32 * 8 / 80.0 / 4
"""An FSK cycle-init minipacket before a rate-0 packet (hilgate's estimate: a quarter of an FSK frame)."""
MINIPACKET_S = 0.5
"""An FSK minipacket: a ping, a ping's reply, an acknowledgement (hilgate's estimate)."""


PACKET_TYPES = {"fsk": 1, "fsk_mini": 2, "psk": 3, "psk_mini": 4}
"""``$CACST``/``$CAXST`` packet type (``libumutil.h``: XST_PKT_FSK, _FSK_MINI, _PSK, _PSK_MINI)."""
RXP_TYPES = {"fsk": 0, "psk": 1}
"""``$CARXP``'s packet type (``libumutil.h``: RXP_PKT_FSK, RXP_PKT_PSK)."""


@dataclass(frozen=True)
class CycleStats:
    """The figures of one ``$CACST`` (version 8), in ``acomms``' names; :func:`cst` formats them."""

    mode: int                # 0 good, 1 bad CRC, 2 timeout
    toa: str                 # YYYYmmddHHMMSS.ffffff
    rate: int
    src: int
    dest: int
    packet_type: int
    num_frames: int
    bad_frames: int
    mfd_peak: int            # comms matched filter: peak (0-32767), power at it (dB), ratio, SPL (dB)
    mfd_pow: int
    mfd_ratio: int
    mfd_spl: int
    agn: int                 # analog gain (dB)
    snr_rss: int             # received signal strength (dB)
    snr_in: float            # input SNR (dB)
    snr_out: float           # equaliser output SNR (dB)
    snr_sym: int             # symbol SNR (-100: not measured)
    mse: float               # equaliser mean square error (dB)
    dqf: int                 # FSK data quality factor (-1 for PSK)
    doppler: float           # m/s
    noise: int               # noise level (dB)
    carrier: int             # Hz
    bandwidth: int           # Hz
    toa_mode: int = 0
    psk_error: int = 0
    shifts: tuple[int, int, int, int] = (0, 0, 0, 0)  # ain, ainp, mfd, p2b
    sequence: int = 0
    data_rate: int = -1      # (version 8's FDP fields: -1, -1, 00 for a packet that is no FDP packet)
    data_frames: int = -1
    bad_data_frames: int = 0


def cst(stats: CycleStats) -> bytes:
    """``$CACST,8,…`` with the widths a Micro-Modem 2 prints (two digits for the time mode, gain and
    shifts, four for the matched filter's ratio and level, three for addresses and the data quality)."""
    s = stats
    return sentence("CACST", 8, s.mode, s.toa, f"{s.toa_mode:02d}", s.mfd_peak, s.mfd_pow, f"{s.mfd_ratio:04d}",
                    f"{s.mfd_spl:04d}", f"{s.agn:02d}", *(f"{x:02d}" for x in s.shifts), s.rate, f"{s.src:03d}",
                    f"{s.dest:03d}", s.psk_error, s.packet_type, s.num_frames, s.bad_frames, s.snr_rss,
                    f"{s.snr_in:.1f}", f"{s.snr_out:.2f}", s.snr_sym, f"{s.mse:.2f}", f"{s.dqf:03d}",
                    f"{s.doppler:.2f}", s.noise, s.carrier, s.bandwidth, s.sequence, s.data_rate, s.data_frames,
                    f"{s.bad_data_frames:02d}")


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
