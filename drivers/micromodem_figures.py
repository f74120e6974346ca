"""What an emulated Micro-Modem's ``$CACST`` says about a reception: the link budget on the modem's scales.

:mod:`hilgate.models.link_budget` gives an RSSI in dB re 1 V (−20 dB at 1 m, spherical spreading and 1 dB/km
of absorption: the transmission loss is −20 − RSSI), an integrity and a closing speed.  A Micro-Modem prints
levels that are positive: a sound pressure level, an SNR, matched-filter figures (a public v8 capture:
``…,06,32767,45,0102,0123,07,…,150,26.0,9.48,-100,-6.48,-01,0.01,51,25000,5000,…``).  The mapping is
hilgate's, stated here once: the SPL is :data:`SOURCE_LEVEL_DB` less the loss, the SNR that less
:data:`NOISE_LEVEL_DB` (so SNR = RSSI + 100, as the emulator printed before); the matched filter's peak and
ratio grow with the SNR (the peak saturates at 32767, as in the capture at short range); no equaliser is
modelled (output SNR = input SNR, no symbol SNR: −100, as the capture prints it); the data quality factor
is the integrity for FSK and −1 for PSK, as the modem prints it.
"""

from __future__ import annotations

from typing import Any

SOURCE_LEVEL_DB = 185  # dB re 1 uPa at 1 m: hilgate's figure for the modem's source level (not a datasheet's)
NOISE_LEVEL_DB = 105   # dB re 1 uPa in the band: hilgate's constant
CARRIER_HZ, BANDWIDTH_HZ = 25000, 5000  # the micromodem preset's band (22.5-27.5 kHz)
PEAK_MAX = 32767


def figures(heard: Any, agn: int, psk: bool) -> dict[str, Any]:
    """``CycleStats`` fields of a reception (``heard``: a ``link_budget.Reception``, None if the model knows no
    sender) for a modem whose ``AGN`` setting is ``agn`` (250 is 30 dB)."""
    rssi = heard.rssi_db if heard is not None else NOISE_LEVEL_DB - SOURCE_LEVEL_DB - 20
    spl = max(0, SOURCE_LEVEL_DB + 20 + rssi)
    snr = spl - NOISE_LEVEL_DB
    integrity = heard.integrity if heard is not None else 0
    return dict(mfd_peak=min(PEAK_MAX, max(0, round(100 * 10 ** (snr / 20)))), mfd_pow=max(0, round(snr)),
                mfd_ratio=min(9999, max(0, round(10 ** (snr / 20)))), mfd_spl=min(9999, spl),
                agn=round(agn * 30 / 250), snr_rss=spl, snr_in=float(snr), snr_out=float(snr), snr_sym=-100,
                mse=-max(0.0, snr) / 2, dqf=-1 if psk else min(255, max(0, integrity)),
                doppler=heard.velocity_mps if heard is not None else 0.0, noise=NOISE_LEVEL_DB,
                carrier=CARRIER_HZ, bandwidth=BANDWIDTH_HZ)
