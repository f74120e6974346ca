"""The physical channel model (``error: {kind: physical}``): each formula against published values or
an independent closed form, the assembled SNR and PER by hand, PER in simulation against the analytic
PER (seeded, z = 5 as in test_error_rates.py), and SINR capture with two overlapping frames."""

import math

import pytest

from hilgate.models.acoustics import (band_noise_db, ber, francois_garrison_db_per_km, noise_psd_db,
                                      thorp_db_per_km, transmission_loss_db)
from hilgate.models.medium import Channel
from hilgate.models.physical import Acoustic, Environment, PhysicalErrorModel
from netkit import Net

Z = 5.0


# -- absorption ------------------------------------------------------------------------------------

@pytest.mark.parametrize("f_khz,published", [
    (1.0, 0.069),    # Thorp (as Stojanovic 2007 writes it, dB/km): 0.069 dB/km at 1 kHz
    (10.0, 1.187),   # 1.19 dB/km at 10 kHz
    (25.0, 6.105),   # 6.1 dB/km at 25 kHz
])
def test_thorp_at_published_frequencies(f_khz, published):
    assert thorp_db_per_km(f_khz) == pytest.approx(published, abs=0.0006)


def test_thorp_low_frequency_form_below_400_hz():
    f = 0.2
    assert thorp_db_per_km(f) == pytest.approx(0.002 + 0.11 * f * f / (1 + f * f) + 0.011 * f * f)


def ainslie_mccolm(f, t, s, z_m, ph):
    """Ainslie & McColm (JASA 103(3) 1671, 1998): their simplified formula, shown to follow Francois–
    Garrison within ~10 % from 100 Hz to 1 MHz; an independent formula to check ours against."""
    z = z_m / 1000.0
    f1 = 0.78 * math.sqrt(s / 35) * math.exp(t / 26)
    f2 = 42 * math.exp(t / 17)
    return (0.106 * f1 * f * f / (f1 * f1 + f * f) * math.exp((ph - 8) / 0.56)
            + 0.52 * (1 + t / 43) * (s / 35) * f2 * f * f / (f2 * f2 + f * f) * math.exp(-z / 6)
            + 0.00049 * f * f * math.exp(-(t / 27 + z / 17)))


@pytest.mark.parametrize("t,s,d,ph", [(4, 35, 1000, 8.0), (10, 35, 10, 8.0), (20, 35, 0, 8.1), (15, 30, 100, 7.9)])
@pytest.mark.parametrize("f", [0.5, 2.0, 7.0, 12.0, 26.0, 63.0, 100.0])
def test_francois_garrison_follows_ainslie_mccolm(t, s, d, ph, f):
    fg = francois_garrison_db_per_km(f, t, s, d, ph)
    assert fg == pytest.approx(ainslie_mccolm(f, t, s, d, ph), rel=0.10)


def test_francois_garrison_near_thorp_at_thorps_conditions():
    """Thorp fitted measurements at about 4 °C and 1 km depth: Francois–Garrison there is close
    (within 20 % from 1 to 25 kHz), and below Thorp at 25 kHz as the literature says."""
    for f in (1, 5, 10, 17, 25):
        assert francois_garrison_db_per_km(f, 4, 35, 1000, 8) == pytest.approx(thorp_db_per_km(f), rel=0.20)
    assert francois_garrison_db_per_km(25, 4, 35, 1000, 8) < thorp_db_per_km(25)


def test_transmission_loss_closed_form():
    assert transmission_loss_db(1000, 1.187, 1.5) == pytest.approx(45 + 1.187)
    assert transmission_loss_db(100, 0.0, 2.0) == pytest.approx(40.0)
    assert transmission_loss_db(0.2, 1.0, 1.5) == pytest.approx(0.001)  # below 1 m: the source's 1 m


# -- noise -------------------------------------------------------------------------------------------

def wenz(f, s, w):
    """The four sources of Stojanovic 2007, eqs. (5)-(8), summed in µPa²/Hz."""
    lg = math.log10
    levels = (17 - 30 * lg(f),
              40 + 20 * (s - 0.5) + 26 * lg(f) - 60 * lg(f + 0.03),
              50 + 7.5 * math.sqrt(w) + 20 * lg(f) - 40 * lg(f + 0.4),
              -15 + 20 * lg(f))
    return 10 * lg(sum(10 ** (x / 10) for x in levels))


@pytest.mark.parametrize("f", [0.1, 1.0, 10.0, 25.0, 50.0, 100.0])
@pytest.mark.parametrize("s,w", [(0.5, 0.0), (0.0, 0.0), (1.0, 10.0)])
def test_noise_spectrum_matches_the_formula(f, s, w):
    assert noise_psd_db(f, s, w) == pytest.approx(wenz(f, s, w), abs=1e-9)


def test_noise_at_10_khz_by_hand():
    # turbulence -13, shipping 66 - 60·log10(10.03) = 5.922, wind 70 - 40·log10(10.4) = 29.319, thermal 5
    assert noise_psd_db(10.0, 0.5, 0.0) == pytest.approx(29.355, abs=0.001)


def test_band_noise_integral_and_centre():
    import numpy as np

    f = np.linspace(18.0, 34.0, 20001)
    psd = 10 ** (np.array([noise_psd_db(x, 0.5, 3.0) for x in f]) / 10)
    area = float(np.sum((psd[1:] + psd[:-1]) / 2 * np.diff(f))) * 1000.0
    assert band_noise_db(18, 34, 0.5, 3.0) == pytest.approx(10 * math.log10(area), abs=0.001)
    centre = noise_psd_db(26.0, 0.5, 3.0) + 10 * math.log10(16000)
    assert band_noise_db(18, 34, 0.5, 3.0, method="centre") == pytest.approx(centre, abs=1e-9)
    # a flat floor far above the ambient noise: the band holds floor + 10·log10(B)
    assert band_noise_db(18, 34, 0.5, 0.0, floor_db=120.0) == pytest.approx(120 + 10 * math.log10(16000), abs=1e-6)


# -- BER ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("modulation,ebn0_db,expected", [
    ("bpsk", 9.5879, 1e-5),           # the textbook 9.6 dB for 1e-5
    ("qpsk", 9.5879, 1e-5),           # Gray QPSK: the same per bit
    ("bfsk-coherent", 12.5982, 1e-5),  # 3 dB worse
    ("bfsk", 10 * math.log10(2 * math.log(0.5 / 1e-5)), 1e-5),  # ½·exp(−g/2) = 1e-5
    ("bpsk", 0.0, 0.5 * math.erfc(1.0)),
    ("bfsk", 0.0, 0.5 * math.exp(-0.5)),
])
def test_ber_closed_forms(modulation, ebn0_db, expected):
    assert ber(modulation, ebn0_db) == pytest.approx(expected, rel=1e-3)


def test_ber_refuses_an_unknown_modulation():
    with pytest.raises(ValueError, match="modulation"):
        ber("ofdm", 10.0)


# -- the assembled model ------------------------------------------------------------------------------

def model(**env):
    return PhysicalErrorModel(Environment(**env), Acoustic((18.0, 34.0), 150.0, modulation="bpsk"), 8000.0)


def test_snr_and_per_by_hand():
    m = model(spreading=1.5, shipping=0.5, wind_mps=0.0)
    d = 2000.0
    tl = 15 * math.log10(d) + thorp_db_per_km(26.0) * 2.0
    snr = 150.0 - tl - band_noise_db(18, 34, 0.5, 0.0)
    assert m.snr_db(d) == pytest.approx(snr, abs=1e-9)
    b = 0.5 * math.erfc(math.sqrt(10 ** ((snr + 10 * math.log10(16000 / 8000)) / 10)))
    assert m.per(d, 32) == pytest.approx(1 - (1 - b) ** 256, rel=1e-9)


def test_level_and_coding_gain():
    base = model()
    quieter = PhysicalErrorModel(Environment(), Acoustic((18.0, 34.0), 150.0, level=3), 8000.0)
    assert quieter.snr_db(500.0) == pytest.approx(base.snr_db(500.0) - 20.0)
    coded = PhysicalErrorModel(Environment(), Acoustic((18.0, 34.0), 150.0, coding_gain_db=3.0), 8000.0)
    assert coded.ber_at_snr(0.0) == pytest.approx(base.ber_at_snr(3.0))


def test_per_grows_with_distance_and_with_frame_length():
    m = model()
    pers = [m.per(d, 64) for d in (100, 1000, 2000, 3000, 4000, 6000)]
    assert pers == sorted(pers) and pers[0] < 1e-12 and pers[-1] > 0.999
    assert m.per(3000, 16) < m.per(3000, 64)


def test_models_compare_and_pickle_by_value():
    import pickle

    a, b = model(), model()
    assert a == b and hash(a) == hash(b) and pickle.loads(pickle.dumps(a)) == a
    assert model(spreading=2.0) != a


# -- in simulation --------------------------------------------------------------------------------------

def distance_for(m, size, target):
    low, high = 1.0, 100_000.0
    for _ in range(100):
        mid = (low + high) / 2
        low, high = (mid, high) if m.per(mid, size) < target else (low, mid)
    return low


@pytest.mark.parametrize("modulation,target", [("bpsk", 0.3), ("bfsk", 0.7)])
def test_loss_fraction_in_simulation_matches_the_analytic_per(modulation, target):
    n, size = 4000, 40
    m = PhysicalErrorModel(Environment(), Acoustic((7.0, 17.0), 141.0, modulation=modulation), 1900.0)
    d = distance_for(m, size, target)
    p = m.per(d, size)
    net = Net(Channel("ac", 1500.0), seed=5)
    net.modem("a", (0, 0, 0), bitrate_bps=1900.0, error=m)
    net.modem("b", (d, 0, 0), bitrate_bps=1900.0, error=m)
    lost = net.lost_of("a", "b", n, size)
    sigma = math.sqrt(n * p * (1 - p))
    assert abs(lost - n * p) <= Z * sigma, (lost, n * p)


def test_the_senders_source_level_applies_on_the_path():
    """The receiver's model is bound to the sender's acoustic front end: a sender at AT!L3 (−20 dB)
    is heard 20 dB lower, whatever the receiver's own level."""
    loud = PhysicalErrorModel(Environment(), Acoustic((7.0, 17.0), 141.0), 1900.0)
    quiet = PhysicalErrorModel(Environment(), Acoustic((7.0, 17.0), 141.0, level=3), 1900.0)
    assert loud.path_from(quiet.acoustic).snr_db(1000) == pytest.approx(loud.snr_db(1000) - 20)
    assert quiet.path_from(loud.acoustic).snr_db(1000) == pytest.approx(loud.snr_db(1000))
    assert loud.path_from(loud.acoustic) is loud and loud.path_from(None, 1900.0) is loud


# -- SINR capture -------------------------------------------------------------------------------------

def capture_net(collisions, capture_db, d_weak):
    env = Environment(collisions=collisions, capture_db=capture_db)
    m = PhysicalErrorModel(env, Acoustic((18.0, 34.0), 160.0), 8000.0)
    net = Net(Channel("ac", 1500.0), seed=3)
    net.modem("r", (0, 0, 0), bitrate_bps=8000.0, error=m)
    net.modem("strong", (100, 0, 0), bitrate_bps=8000.0, error=m)
    net.modem("weak", (0, d_weak, 0), bitrate_bps=8000.0, error=m)
    # both arrive at r over the same stretch of time: same size, sent so that they overlap by half
    tau_s, tau_w = 100 / 1500.0, d_weak / 1500.0
    strong = net.send("strong", "r", 100, at=1.0 - tau_s)
    weak = net.send("weak", "r", 100, at=1.0 - tau_w + 0.05)
    net.run()
    net.names = {strong.id: "strong", weak.id: "weak"}
    return m, net


def outcome(net):
    got = {net.names[frame]: "rx" for _, _, _, frame, _ in net.of("rx", "r")}
    got.update({net.names[frame]: cause for _, _, _, frame, cause in net.of("err", "r")})
    return got


def test_strict_overlap_is_the_default():
    _, net = capture_net("overlap", 10.0, 1000.0)
    assert outcome(net) == {"strong": "col", "weak": "col"}


def test_sinr_capture_keeps_the_stronger_frame():
    m, net = capture_net("sinr", 10.0, 1000.0)
    # known powers: the strong arrival is 15·log10(10) + (1 − 0.1)·α(26 kHz) dB above the weak one
    margin = m.received_db(100.0) - m.received_db(1000.0)
    assert margin == pytest.approx(15.0 + 0.9 * thorp_db_per_km(26.0))
    assert margin > 10.0
    assert m.per_sinr(100.0, 100, m.rx_power(1000.0)) < 1e-9  # the survivor is not lost to noise either
    # the weak frame is collided, and at its SINR (−margin) its bits are lost too: cause mult
    assert m.per_sinr(1000.0, 100, m.rx_power(100.0)) == 1.0
    assert outcome(net) == {"strong": "rx", "weak": "mult"}


def test_sinr_capture_threshold_either_side_of_the_margin():
    """The signal-to-interference ratio is the power margin (noise is not interference): half a dB
    above it nothing is captured, half a dB below it the stronger frame is."""
    m, _ = capture_net("sinr", 10.0, 1000.0)
    margin = m.received_db(100.0) - m.received_db(1000.0)
    assert outcome(capture_net("sinr", margin + 0.5, 1000.0)[1]) == {"strong": "col", "weak": "mult"}
    assert outcome(capture_net("sinr", margin - 0.5, 1000.0)[1]) == {"strong": "rx", "weak": "mult"}


# -- any valid configuration ----------------------------------------------------------------------------

from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=200, deadline=None)
@given(
    low=st.floats(0.5, 100), width=st.floats(0.5, 100), sl=st.floats(80, 220), level=st.integers(0, 3),
    modulation=st.sampled_from(["bpsk", "qpsk", "bfsk", "bfsk-coherent"]), gain=st.floats(0, 30),
    absorption=st.sampled_from(["thorp", "francois-garrison"]), k=st.floats(1, 2), s=st.floats(0, 1),
    w=st.floats(0, 100), floor=st.one_of(st.none(), st.floats(-100, 200)), bitrate=st.floats(1, 1e6),
    t=st.floats(-2, 40), sal=st.floats(0, 45), depth=st.floats(0, 11000), ph=st.floats(6, 10),
)
def test_any_valid_configuration_gives_a_per_that_grows_with_distance(low, width, sl, level, modulation, gain,
                                                                     absorption, k, s, w, floor, bitrate, t, sal,
                                                                     depth, ph):
    env = Environment(absorption=absorption, spreading=k, shipping=s, wind_mps=w, noise_floor_db=floor,
                      temperature_c=t, salinity_ppt=sal, depth_m=depth, ph=ph)
    m = PhysicalErrorModel(env, Acoustic((low, low + width), sl, level, modulation, gain), bitrate)
    pers = [m.per(d, 64) for d in (0.0, 0.5, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5)]
    assert all(0.0 <= p <= 1.0 for p in pers)
    assert all(a <= b + 1e-12 for a, b in zip(pers, pers[1:]))
