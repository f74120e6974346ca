"""An underwater acoustic link budget written from the textbooks, apart from hilgate's own code
(``models/acoustics.py``, ``models/physical.py``), to check it on pairs whose ends differ.

Sources, as a newcomer would read them:
- Thorp's absorption, as Stojanovic (2007, eq. 3) writes it in dB/km for f in kHz, with the
  low-frequency form below 0.4 kHz (Urick / Jensen et al.).
- Francois & Garrison (JASA 72(6) 1879, 1982): boric acid, magnesium sulphate, pure water.
- Ambient noise: Coates's / Stojanovic's four sources in dB re 1 µPa²/Hz; its power over a band is
  integrated here by Gauss–Legendre quadrature (hilgate uses Simpson's rule), or taken at the band
  centre times the bandwidth.
- BER over AWGN (Proakis): coherent BPSK / Gray QPSK ½·erfc(√γ), coherent BFSK ½·erfc(√(γ/2)),
  non-coherent BFSK ½·exp(−γ/2); PER = 1 − (1 − BER)^(8L).

What a mixed pair means is docs/channel-models.md's rule: the sender's source level with its AT!L
step, bit rate, modulation and coding gain; the receiver's water, noise over its band and bandwidth;
where the bands partly overlap, the in-band fraction of the sender's power, absorbed at the centre
of the overlap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

AT_L_DB = {0: 0.0, 1: -6.0, 2: -12.0, 3: -20.0}  # EvoLogics AT!L steps


@dataclass(frozen=True)
class Front:
    low_khz: float
    high_khz: float
    sl_db: float
    level: int = 0
    modulation: str = "bpsk"
    gain_db: float = 0.0
    bitrate: float = 1000.0


@dataclass(frozen=True)
class Water:
    absorption: str = "thorp"
    k: float = 1.5
    shipping: float = 0.5
    wind: float = 0.0
    floor_db: float | None = None
    noise_band: str = "integral"
    t: float = 10.0
    s: float = 35.0
    depth: float = 10.0
    ph: float = 8.0


def thorp(f: float) -> float:
    f2 = f * f
    if f < 0.4:
        return 0.002 + 0.11 * f2 / (1 + f2) + 0.011 * f2
    return 0.11 * f2 / (1 + f2) + 44 * f2 / (4100 + f2) + 2.75e-4 * f2 + 0.003


def francois_garrison(f: float, t: float, s: float, depth: float, ph: float) -> float:
    c = 1412 + 3.21 * t + 1.19 * s + 0.0167 * depth
    theta = 273 + t
    f1 = 2.8 * (s / 35) ** 0.5 * 10 ** (4 - 1245 / theta)
    boric = 8.86 / c * 10 ** (0.78 * ph - 5) * f1 * f * f / (f * f + f1 * f1)
    f2 = 8.17 * 10 ** (8 - 1990 / theta) / (1 + 0.0018 * (s - 35))
    mg = 21.44 * s / c * (1 + 0.025 * t) * (1 - 1.37e-4 * depth + 6.2e-9 * depth ** 2) * f2 * f * f / (f * f + f2 * f2)
    if t <= 20:
        a3 = 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t ** 2 - 1.50e-8 * t ** 3
    else:
        a3 = 3.964e-4 - 1.146e-5 * t + 1.45e-7 * t ** 2 - 6.5e-10 * t ** 3
    water = a3 * (1 - 3.83e-5 * depth + 4.9e-10 * depth ** 2) * f * f
    return boric + mg + water


def noise_psd(f, shipping: float, wind: float, floor_db: float | None):
    """Linear µPa²/Hz at f kHz (array or number)."""
    f = np.asarray(f, dtype=float)
    turbulence = 17 - 30 * np.log10(f)
    ships = 40 + 20 * (shipping - 0.5) + 26 * np.log10(f) - 60 * np.log10(f + 0.03)
    waves = 50 + 7.5 * wind ** 0.5 + 20 * np.log10(f) - 40 * np.log10(f + 0.4)
    thermal = -15 + 20 * np.log10(f)
    total = sum(10 ** (x / 10) for x in (turbulence, ships, waves, thermal))
    return total + (10 ** (floor_db / 10) if floor_db is not None else 0.0)


def noise_db(low: float, high: float, water: Water) -> float:
    """Noise power over [low, high] kHz in dB re 1 µPa²."""
    if water.noise_band == "centre":
        return 10 * math.log10(float(noise_psd((low + high) / 2, water.shipping, water.wind, water.floor_db))
                               * (high - low) * 1000)
    nodes, weights = np.polynomial.legendre.leggauss(48)
    edges = np.linspace(low, high, 33)
    total = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        f = (b - a) / 2 * nodes + (a + b) / 2
        total += float(np.sum(weights * noise_psd(f, water.shipping, water.wind, water.floor_db))) * (b - a) / 2
    return 10 * math.log10(total * 1000)


def absorption(f: float, water: Water) -> float:
    if water.absorption == "thorp":
        return thorp(f)
    return francois_garrison(f, water.t, water.s, water.depth, water.ph)


def snr_db(d: float, tx: Front, rx: Front, water: Water) -> float:
    low, high = max(tx.low_khz, rx.low_khz), min(tx.high_khz, rx.high_khz)
    assert low < high, "no overlap: nothing is received"
    share = (high - low) / (tx.high_khz - tx.low_khz)
    signal = tx.sl_db + AT_L_DB[tx.level] + 10 * math.log10(share)
    r = max(d, 1.0)  # the source level is referred to 1 m
    tl = water.k * 10 * math.log10(r) + absorption((low + high) / 2, water) * r / 1000
    return signal - tl - noise_db(rx.low_khz, rx.high_khz, water)


def bit_error_rate(modulation: str, ebn0_db: float) -> float:
    g = 10 ** (ebn0_db / 10)
    if modulation in ("bpsk", "qpsk"):
        return 0.5 * math.erfc(math.sqrt(g))
    if modulation == "bfsk-coherent":
        return 0.5 * math.erfc(math.sqrt(g / 2))
    if modulation == "bfsk":
        return 0.5 * math.exp(-g / 2)
    raise ValueError(modulation)


def per(d: float, size: int, tx: Front, rx: Front, water: Water) -> float:
    ebn0 = snr_db(d, tx, rx, water) + 10 * math.log10((rx.high_khz - rx.low_khz) * 1000 / tx.bitrate) + tx.gain_db
    b = bit_error_rate(tx.modulation, ebn0)
    return -math.expm1(8 * size * math.log1p(-b)) if b < 1 else 1.0


def distance_for(target: float, size: int, tx: Front, rx: Front, water: Water) -> float:
    """Where the PER first reaches ``target`` (bisection on a log scale; the PER grows with d)."""
    low, high = 1.0, 1e6
    for _ in range(200):
        mid = math.sqrt(low * high)
        low, high = (mid, high) if per(mid, size, tx, rx, water) < target else (low, mid)
    return math.sqrt(low * high)
