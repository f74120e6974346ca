"""A frame-loss model computed from the physics of the link instead of a user's BER(d) expression.

``error: {kind: physical}`` on a link (with the modem's ``acoustic:`` front end, usually from a
preset) gives, for a frame of L bytes heard at distance d:

    SNR(d)  = SL − TL(d) − NL                 SL: the sender's source level (AT!L steps applied)
    TL(d)   = k·10·log10(d) + α(fc)·d/1000    Thorp or Francois–Garrison at the band centre fc
    NL      = 10·log10 ∫band N(f) df          Wenz/Stojanovic noise (+ a flat floor), or N(fc)·B
    Eb/N0   = SNR + 10·log10(B / R) + G       B bandwidth, R bit rate, G coding gain
    PER     = 1 − (1 − BER(Eb/N0))^(8L)

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

import math
from dataclasses import dataclass, replace

from .acoustics import (MODULATIONS, band_noise_db, ber, db_to_linear, francois_garrison_db_per_km,
                        thorp_db_per_km, transmission_loss_db)

__all__ = ["Environment", "Acoustic", "PhysicalErrorModel", "LEVEL_DB", "ABSORPTION", "NOISE_BAND", "COLLISIONS"]

LEVEL_DB = (0.0, -6.0, -12.0, -20.0)
"""EvoLogics ``AT!L`` source level steps: 0 is the maximum, then −6, −12 and −20 dB."""
ABSORPTION = ("thorp", "francois-garrison")
NOISE_BAND = ("integral", "centre")
COLLISIONS = ("overlap", "sinr")


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
    """The modem's acoustic front end (a link's ``acoustic:`` key; presets give it)."""

    band_khz: tuple[float, float]
    source_level_db: float           # dB re 1 µPa @ 1 m at AT!L0 (maximum)
    level: int = 0                   # AT!L 0..3
    modulation: str = "bpsk"
    coding_gain_db: float = 0.0

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


class PhysicalErrorModel:
    """The receiving modem's loss model, from physics (see the module's docstring).

    ``source_db`` is what the sender emits: by default the receiver's own ``acoustic`` (modems of a
    scene usually share a preset); the medium binds each path to its real sender with
    :meth:`path_from`."""

    __slots__ = ("env", "acoustic", "bitrate_bps", "source_db", "alpha_db_per_km", "noise_db", "noise_power",
                 "ebn0_offset_db", "capture", "unit", "constant_zero", "sinr")

    def __init__(self, env: Environment, acoustic: Acoustic, bitrate_bps: float, source_db: float | None = None):
        if acoustic.modulation not in MODULATIONS:
            raise ValueError(f"modulation must be one of {', '.join(MODULATIONS)}, not {acoustic.modulation!r}")
        if env.absorption not in ABSORPTION:
            raise ValueError(f"absorption must be one of {', '.join(ABSORPTION)}, not {env.absorption!r}")
        low, high = acoustic.band_khz
        if not 0 < low < high:
            raise ValueError(f"band_khz must be [low, high] with 0 < low < high, not [{low:g}, {high:g}]")
        self.env = env
        self.acoustic = acoustic
        self.bitrate_bps = float(bitrate_bps)
        self.source_db = acoustic.emitted_db if source_db is None else source_db
        fc = acoustic.centre_khz
        if env.absorption == "thorp":
            self.alpha_db_per_km = thorp_db_per_km(fc)
        else:
            self.alpha_db_per_km = francois_garrison_db_per_km(fc, env.temperature_c, env.salinity_ppt, env.depth_m,
                                                               env.ph)
        self.noise_db = band_noise_db(low, high, env.shipping, env.wind_mps, env.noise_floor_db, env.noise_band)
        self.noise_power = db_to_linear(self.noise_db)
        self.ebn0_offset_db = 10.0 * math.log10(acoustic.bandwidth_hz / self.bitrate_bps) + acoustic.coding_gain_db
        self.capture = db_to_linear(env.capture_db)
        self.sinr = env.collisions == "sinr"
        self.unit = "physical"
        self.constant_zero = False

    # -- the link budget -------------------------------------------------------------------------

    def transmission_loss_db(self, d: float) -> float:
        return transmission_loss_db(d, self.alpha_db_per_km, self.env.spreading)

    def received_db(self, d: float) -> float:
        """Received level in dB re 1 µPa² at ``d`` metres."""
        return self.source_db - transmission_loss_db(d, self.alpha_db_per_km, self.env.spreading)

    def rx_power(self, d: float) -> float:
        """Received power (µPa², linear) at ``d``: what an overlapping arrival adds to the noise."""
        return db_to_linear(self.received_db(d))

    def snr_db(self, d: float) -> float:
        return self.received_db(d) - self.noise_db

    def ber_at_snr(self, snr_db: float) -> float:
        return ber(self.acoustic.modulation, snr_db + self.ebn0_offset_db)

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

    def path_from(self, sender_error: object) -> "PhysicalErrorModel":
        """This receiver's model on the path from a sender whose error model is ``sender_error``: a
        physical sender's own source level (with its AT!L step) replaces the assumed one."""
        if isinstance(sender_error, PhysicalErrorModel) and sender_error.acoustic.emitted_db != self.source_db:
            return PhysicalErrorModel(self.env, self.acoustic, self.bitrate_bps, sender_error.acoustic.emitted_db)
        return self

    def with_env(self, **changes: object) -> "PhysicalErrorModel":
        """A copy with other environment values (``hilgate fit`` varies spreading and the floor)."""
        return PhysicalErrorModel(replace(self.env, **changes), self.acoustic, self.bitrate_bps, self.source_db)

    # -- value semantics (a reload compares specs by value; a worker pickles them) --------------

    def _key(self) -> tuple:
        return (self.env, self.acoustic, self.bitrate_bps, self.source_db)

    def __reduce__(self):
        return (PhysicalErrorModel, self._key())

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PhysicalErrorModel):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        a = self.acoustic
        return (f"PhysicalErrorModel({a.band_khz[0]:g}-{a.band_khz[1]:g} kHz, SL {self.source_db:g} dB, "
                f"{a.modulation}, {self.env.absorption}, k={self.env.spreading:g})")
