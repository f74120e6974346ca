"""The physics of an underwater acoustic link, as published formulas: absorption, spreading, ambient
noise, and the bit error rate of a modulation at a given Eb/N0.

Pure functions of numbers (no state, no I/O), so that each can be checked against its source's
published values.  :mod:`.physical` assembles them into an error model.  Units follow the sources:
frequencies in kHz, distances in metres, levels in dB re 1 µPa (spectral levels per Hz).

- Thorp's absorption (as Stojanovic, "On the relationship between capacity and distance in an
  underwater acoustic communication channel", 2007, writes it, in dB/km; ns-3's ``UanPropModelThorp``
  uses the same), with the low-frequency form below 0.4 kHz.
- Francois & Garrison (JASA 72(3) 896–907 and 72(6) 1879–1890, 1982): boric acid, magnesium sulphate
  and pure water, for temperature, salinity, depth and pH.  Thirty lines of our own rather than a
  dependency: ``arlpy`` has it, but brings scipy, bokeh and pandas for one formula.
- Ambient noise, Wenz's curves in Coates's / Stojanovic's closed form: turbulence, shipping (activity
  s in [0, 1]), wind (w in m/s) and thermal noise.
- BER: coherent BPSK / Gray QPSK Q(√(2·Eb/N0)), coherent BFSK Q(√(Eb/N0)), non-coherent BFSK
  ½·exp(−Eb/N0 / 2).
"""

from __future__ import annotations

import math

__all__ = [
    "thorp_db_per_km", "francois_garrison_db_per_km", "transmission_loss_db", "noise_psd_db",
    "band_noise_db", "ber", "MODULATIONS", "db_to_linear", "linear_to_db",
]

MODULATIONS = ("bpsk", "qpsk", "bfsk", "bfsk-coherent")
"""``bfsk`` is non-coherent binary FSK (what most acoustic FSK modems do); ``bfsk-coherent`` is coherent."""


def db_to_linear(db: float) -> float:
    return 10.0 ** (db / 10.0)


def linear_to_db(x: float) -> float:
    return 10.0 * math.log10(x) if x > 0 else -math.inf


def thorp_db_per_km(f_khz: float) -> float:
    """Thorp's absorption coefficient in dB/km at ``f_khz`` (valid above a few hundred Hz; below
    0.4 kHz the low-frequency form 0.002 + 0.11·f²/(1 + f²) + 0.011·f²)."""
    f2 = f_khz * f_khz
    if f_khz >= 0.4:
        return 0.11 * f2 / (1.0 + f2) + 44.0 * f2 / (4100.0 + f2) + 2.75e-4 * f2 + 0.003
    return 0.002 + 0.11 * f2 / (1.0 + f2) + 0.011 * f2


def francois_garrison_db_per_km(f_khz: float, temperature_c: float = 10.0, salinity_ppt: float = 35.0,
                                depth_m: float = 10.0, ph: float = 8.0) -> float:
    """Francois–Garrison absorption in dB/km: boric acid + MgSO4 relaxations + pure-water viscosity.
    The sound speed is their own c = 1412 + 3.21·T + 1.19·S + 0.0167·D."""
    t, s, d, f2 = temperature_c, salinity_ppt, depth_m, f_khz * f_khz
    tk = 273.0 + t
    c = 1412.0 + 3.21 * t + 1.19 * s + 0.0167 * d
    # boric acid
    a1 = 8.86 / c * 10.0 ** (0.78 * ph - 5.0)
    f1 = 2.8 * math.sqrt(s / 35.0) * 10.0 ** (4.0 - 1245.0 / tk)
    boric = a1 * f1 * f2 / (f2 + f1 * f1)
    # magnesium sulphate
    a2 = 21.44 * s / c * (1.0 + 0.025 * t)
    p2 = 1.0 - 1.37e-4 * d + 6.2e-9 * d * d
    f2_mg = 8.17 * 10.0 ** (8.0 - 1990.0 / tk) / (1.0 + 0.0018 * (s - 35.0))
    mgso4 = a2 * p2 * f2_mg * f2 / (f2 + f2_mg * f2_mg)
    # pure water
    if t <= 20.0:
        a3 = 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t * t - 1.50e-8 * t ** 3
    else:
        a3 = 3.964e-4 - 1.146e-5 * t + 1.45e-7 * t * t - 6.5e-10 * t ** 3
    p3 = 1.0 - 3.83e-5 * d + 4.9e-10 * d * d
    return boric + mgso4 + a3 * p3 * f2


def transmission_loss_db(d_m: float, alpha_db_per_km: float, spreading: float = 1.5) -> float:
    """TL = k·10·log10(d) + α·d/1000 (d in metres, referred to 1 m; distances below 1 m count as 1 m,
    where the source level is defined)."""
    d = d_m if d_m > 1.0 else 1.0
    return spreading * 10.0 * math.log10(d) + alpha_db_per_km * d / 1000.0


def noise_psd_db(f_khz: float, shipping: float = 0.5, wind_mps: float = 0.0) -> float:
    """Ambient noise power spectral density in dB re 1 µPa²/Hz at ``f_khz`` (Wenz's sources summed)."""
    lf = math.log10(f_khz)
    turbulence = 17.0 - 30.0 * lf
    ship = 40.0 + 20.0 * (shipping - 0.5) + 26.0 * lf - 60.0 * math.log10(f_khz + 0.03)
    wind = 50.0 + 7.5 * math.sqrt(wind_mps) + 20.0 * lf - 40.0 * math.log10(f_khz + 0.4)
    thermal = -15.0 + 20.0 * lf
    return linear_to_db(db_to_linear(turbulence) + db_to_linear(ship) + db_to_linear(wind) + db_to_linear(thermal))


def band_noise_db(f_low_khz: float, f_high_khz: float, shipping: float = 0.5, wind_mps: float = 0.0,
                  floor_db: float | None = None, method: str = "integral", steps: int = 256) -> float:
    """Noise power in the band in dB re 1 µPa²: the PSD (plus a flat ``floor_db`` per Hz, e.g. a tank's
    measured floor) integrated over [f_low, f_high] by Simpson's rule, or (``method="centre"``, what
    ns-3's ``UanPhyGen`` does) the PSD at the band centre times the bandwidth."""
    floor = db_to_linear(floor_db) if floor_db is not None else 0.0

    def psd(f_khz: float) -> float:
        return db_to_linear(noise_psd_db(f_khz, shipping, wind_mps)) + floor

    bandwidth_hz = (f_high_khz - f_low_khz) * 1000.0
    if method == "centre":
        return linear_to_db(psd((f_low_khz + f_high_khz) / 2.0) * bandwidth_hz)
    n = steps + steps % 2
    h = (f_high_khz - f_low_khz) / n
    total = psd(f_low_khz) + psd(f_high_khz)
    for i in range(1, n):
        total += (4.0 if i % 2 else 2.0) * psd(f_low_khz + i * h)
    return linear_to_db(total * h / 3.0 * 1000.0)


def _q(x: float) -> float:
    return 0.5 * math.erfc(x / math.sqrt(2.0))


def ber(modulation: str, ebn0_db: float) -> float:
    """Bit error rate at Eb/N0 (dB) over an additive white Gaussian noise channel."""
    g = db_to_linear(ebn0_db)
    if modulation in ("bpsk", "qpsk"):
        return _q(math.sqrt(2.0 * g))
    if modulation == "bfsk-coherent":
        return _q(math.sqrt(g))
    if modulation == "bfsk":
        return 0.5 * math.exp(-g / 2.0)
    raise ValueError(f"modulation must be one of {', '.join(MODULATIONS)}, not {modulation!r}")
