"""A frame-loss model computed from the physics of the link instead of a user's BER(d) expression.

``error: {kind: physical}`` on a link (with the modem's ``acoustic:`` front end, usually from a
preset) gives, for a frame of L bytes heard at distance d:

    SNR(d)  = SL − TL(d) − NL                 SL: the sender's source level (AT!L steps applied)
    TL(d)   = k·10·log10(d) + α(fc)·d/1000    Thorp or Francois–Garrison at the band centre fc
    NL      = 10·log10 ∫band N(f) df          Wenz/Stojanovic noise (+ a flat floor), or N(fc)·B
    Eb/N0   = SNR + 10·log10(B / R) + G       B bandwidth, R bit rate, G coding gain
    PER     = 1 − (1 − BER(Eb/N0))^(8L)

On a path the sender gives the transmit side (SL with its AT!L step, R, the modulation of the BER,
G, its band) and the receiver the receive side (its water, its band's noise NL, B); where the two
bands differ, SL keeps the share of the sender's band inside the receiver's and fc is the centre of
that overlap (:class:`PhysicalErrorModel`).

the way ns-3's UAN module (``UanPropModelThorp``, ``UanNoiseModelDefault``, ``UanPhyGen``) and
DESERT's physical layers chain them.  The object has the error model's interface (``per(d, size)``)
so the medium and the radio use it as they use an expression; everything that depends only on the
configuration (α, the band's noise power, the Eb/N0 offset) is computed once here, so a PER costs a
logarithm, an ``erfc`` and a ``log1p`` (O(1); the medium also caches it per static pair and size).

With ``collisions: sinr`` the receiving radio adds the received power of overlapping arrivals to the
noise (:meth:`per_sinr`) and drops an arrival whose signal-to-interference ratio is below
``capture_db`` instead of dropping every overlapping arrival.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from .acoustics import (MODULATIONS, band_noise_db, ber, db_to_linear, francois_garrison_db_per_km,
                        thorp_db_per_km, transmission_loss_db)

__all__ = ["Environment", "Acoustic", "PhysicalErrorModel", "LEVEL_DB", "ABSORPTION", "NOISE_BAND", "COLLISIONS",
           "BAND", "MODULATION"]

LEVEL_DB = (0.0, -6.0, -12.0, -20.0)
"""EvoLogics ``AT!L`` source level steps: 0 is the maximum, then −6, −12 and −20 dB."""
ABSORPTION = ("thorp", "francois-garrison")
NOISE_BAND = ("integral", "centre")
COLLISIONS = ("overlap", "sinr")
BAND = "band"
"""Why a receiver takes nothing from a sender whose band does not overlap its own (the trace's cause)."""
MODULATION = "modulation"
"""Why a receiver cannot decode a sender in its band that uses a modulation it does not decode."""


@dataclass(frozen=True)
class Environment:
    """Where the link is: the water and its noise (the ``error:`` block of kind ``physical``)."""

    absorption: str = "thorp"
    spreading: float = 1.5           # k: 1 cylindrical, 2 spherical, 1.5 "practical"
    shipping: float = 0.5            # s in [0, 1]
    wind_mps: float = 0.0
    noise_floor_db: float | None = None  # flat extra noise, dB re 1 µPa²/Hz
    noise_band: str = "integral"
    temperature_c: float = 10.0      # Francois–Garrison only
    salinity_ppt: float = 35.0
    depth_m: float = 10.0
    ph: float = 8.0
    collisions: str = "overlap"
    capture_db: float = 10.0


@dataclass(frozen=True)
class Acoustic:
    """A modem's acoustic front end (a link's ``acoustic:`` key; presets give it).  As a sender it is
    the transmit side of every path from the modem (level, band, modulation, coding); as a receiver
    its band sets the noise and which senders it hears at all, and its modulation (with ``decodes``)
    which it can decode."""

    band_khz: tuple[float, float]
    source_level_db: float           # dB re 1 µPa @ 1 m at AT!L0 (maximum)
    level: int = 0                   # AT!L 0..3
    modulation: str = "bpsk"
    coding_gain_db: float = 0.0
    decodes: tuple[str, ...] = ()    # modulations it decodes besides its own (a multi-mode receiver)
    delay_spread_s: float | None = None  # the RMS delay spread it tolerates (a BELLHOP channel: above, lost)

    @property
    def centre_khz(self) -> float:
        return (self.band_khz[0] + self.band_khz[1]) / 2.0

    @property
    def bandwidth_hz(self) -> float:
        return (self.band_khz[1] - self.band_khz[0]) * 1000.0

    @property
    def emitted_db(self) -> float:
        """The source level this modem transmits at, its ``AT!L`` step applied."""
        return self.source_level_db + LEVEL_DB[self.level]

    def overlap_khz(self, sender: "Acoustic") -> tuple[float, float] | None:
        """The part of ``sender``'s band inside this receiver's band (None when they do not overlap;
        bands that only touch do not overlap)."""
        low = max(self.band_khz[0], sender.band_khz[0])
        high = min(self.band_khz[1], sender.band_khz[1])
        return (low, high) if low < high else None

    def refuses(self, sender: "Acoustic") -> str | None:
        """Why this receiver cannot take a frame from ``sender``: ``"band"`` (no overlap: it does not
        hear it at all), ``"modulation"`` (it hears it, as interference, but cannot decode it), or None."""
        if self.overlap_khz(sender) is None:
            return BAND
        if sender.modulation != self.modulation and sender.modulation not in self.decodes:
            return MODULATION
        return None


class PhysicalErrorModel:
    """The receiving modem's loss model, from physics (see the module's docstring), on the path from
    one sender.

    ``acoustic`` and ``env`` are the receiving side (its band's noise, its water); ``sender`` and
    ``sender_bitrate_bps`` the transmitting side (source level with its ``AT!L`` step, band,
    modulation, coding, bit rate).  Without a sender the receiver's own front end and ``bitrate_bps``
    stand in (a sender set alike); the medium binds each path to its real sender with
    :meth:`path_from`, once per pair.

    A sender whose band only partly overlaps the receiver's is heard with the in-band fraction of its
    power (its power spread evenly over its band), absorbed at the centre of the overlap; the noise is
    the receiver's over its whole band, so Eb/N0 = SNR + 10·log10(B_receiver / R_sender) + G_sender."""

    __slots__ = ("env", "acoustic", "bitrate_bps", "sender", "sender_bitrate_bps", "source_db", "in_band_db",
                 "signal_db", "alpha_db_per_km", "noise_db", "noise_power", "ebn0_offset_db", "modulation",
                 "capture", "unit", "constant_zero", "sinr")

    def __init__(self, env: Environment, acoustic: Acoustic, bitrate_bps: float, sender: Acoustic | None = None,
                 sender_bitrate_bps: float | None = None):
        sender = acoustic if sender is None else sender
        for front in (acoustic, sender):
            if front.modulation not in MODULATIONS:
                raise ValueError(f"modulation must be one of {', '.join(MODULATIONS)}, not {front.modulation!r}")
            low, high = front.band_khz
            if not 0 < low < high:
                raise ValueError(f"band_khz must be [low, high] with 0 < low < high, not [{low:g}, {high:g}]")
        if env.absorption not in ABSORPTION:
            raise ValueError(f"absorption must be one of {', '.join(ABSORPTION)}, not {env.absorption!r}")
        overlap = acoustic.overlap_khz(sender)
        if overlap is None:
            raise ValueError(f"the sender's band {sender.band_khz[0]:g}-{sender.band_khz[1]:g} kHz is outside the "
                             f"receiver's {acoustic.band_khz[0]:g}-{acoustic.band_khz[1]:g} kHz")
        self.env = env
        self.acoustic = acoustic
        self.bitrate_bps = float(bitrate_bps)
        self.sender = sender
        self.sender_bitrate_bps = self.bitrate_bps if sender_bitrate_bps is None else float(sender_bitrate_bps)
        self.source_db = sender.emitted_db
        if overlap == sender.band_khz:
            self.in_band_db = 0.0
        else:
            self.in_band_db = 10.0 * math.log10((overlap[1] - overlap[0]) * 1000.0 / sender.bandwidth_hz)
        self.signal_db = self.source_db + self.in_band_db
        fc = (overlap[0] + overlap[1]) / 2.0
        if env.absorption == "thorp":
            self.alpha_db_per_km = thorp_db_per_km(fc)
        else:
            self.alpha_db_per_km = francois_garrison_db_per_km(fc, env.temperature_c, env.salinity_ppt, env.depth_m,
                                                               env.ph)
        low, high = acoustic.band_khz
        self.noise_db = band_noise_db(low, high, env.shipping, env.wind_mps, env.noise_floor_db, env.noise_band)
        self.noise_power = db_to_linear(self.noise_db)
        self.ebn0_offset_db = (10.0 * math.log10(acoustic.bandwidth_hz / self.sender_bitrate_bps)
                               + sender.coding_gain_db)
        self.modulation = sender.modulation
        self.capture = db_to_linear(env.capture_db)
        self.sinr = env.collisions == "sinr"
        self.unit = "physical"
        self.constant_zero = False

    # -- the link budget -------------------------------------------------------------------------

    def transmission_loss_db(self, d: float) -> float:
        return transmission_loss_db(d, self.alpha_db_per_km, self.env.spreading)

    def received_db(self, d: float) -> float:
        """Received level in the receiver's band, in dB re 1 µPa², at ``d`` metres."""
        return self.signal_db - transmission_loss_db(d, self.alpha_db_per_km, self.env.spreading)

    def rx_power(self, d: float) -> float:
        """Received power (µPa², linear) at ``d``: what an overlapping arrival adds to the noise."""
        return db_to_linear(self.received_db(d))

    def snr_db(self, d: float) -> float:
        return self.received_db(d) - self.noise_db

    def ber_at_snr(self, snr_db: float) -> float:
        return ber(self.modulation, snr_db + self.ebn0_offset_db)

    def per_at_snr(self, snr_db: float, size: int) -> float:
        b = self.ber_at_snr(snr_db)
        if b <= 0.0:
            return 0.0
        if b >= 1.0:
            return 1.0
        return -math.expm1(8 * size * math.log1p(-b))

    # -- the error model's interface -----------------------------------------------------------

    def per(self, d: float, size: int) -> float:
        """Probability that a frame of ``size`` bytes is lost at ``d`` metres (no interference)."""
        return self.per_at_snr(self.snr_db(d), size)

    def per_sinr(self, d: float, size: int, interference: float) -> float:
        """PER with ``interference`` (µPa², the summed power of overlapping arrivals) added to the noise."""
        sinr = self.received_db(d) - 10.0 * math.log10(self.noise_power + interference)
        return self.per_at_snr(sinr, size)

    def path_from(self, sender: Acoustic | None, bitrate_bps: float | None = None) -> "PhysicalErrorModel":
        """This receiver's model on the path from a sender with front end ``sender`` (None: the scene
        gives it none, and this receiver's own stands in) sending at ``bitrate_bps`` (None: this
        link's own).  The bands must overlap (:meth:`Acoustic.refuses` says so first)."""
        sender = self.acoustic if sender is None else sender
        rate = self.bitrate_bps if bitrate_bps is None else float(bitrate_bps)
        if sender == self.sender and rate == self.sender_bitrate_bps:
            return self
        return _bound(self.env, self.acoustic, self.bitrate_bps, sender, rate)

    # -- value semantics (a reload compares specs by value; a worker pickles them) --------------

    def _key(self) -> tuple:
        return (self.env, self.acoustic, self.bitrate_bps, self.sender, self.sender_bitrate_bps)

    def __reduce__(self):
        return (PhysicalErrorModel, self._key())

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PhysicalErrorModel):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        a, s = self.acoustic, self.sender
        heard = "" if s == a else f" from {s.band_khz[0]:g}-{s.band_khz[1]:g} kHz"
        return (f"PhysicalErrorModel({a.band_khz[0]:g}-{a.band_khz[1]:g} kHz{heard}, SL {self.source_db:g} dB, "
                f"{self.modulation}, {self.sender_bitrate_bps:g} bit/s, {self.env.absorption}, "
                f"k={self.env.spreading:g})")


@functools.lru_cache(maxsize=4096)
def _bound(env: Environment, acoustic: Acoustic, bitrate_bps: float, sender: Acoustic,
           sender_bitrate_bps: float) -> PhysicalErrorModel:
    """One model per distinct (receiver, sender) configuration: a scene of a thousand links in two
    groups binds a million pairs from a handful of models (each costs a noise integral)."""
    return PhysicalErrorModel(env, acoustic, bitrate_bps, sender, sender_bitrate_bps)
