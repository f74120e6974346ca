"""Paths whose two ends differ (issue 32): the sender's transmit side (source level and AT!L step, bit
rate, modulation, coding gain, band) and the receiver's receive side (its water, its band's noise),
whatever error model each end uses for its own traffic.

Checked against ``textbook_acoustics.py``, a link budget written from the textbooks apart from
hilgate's code: exactly where the model is exact (``hilgate check``'s SNR within 0.1 dB, PER within
1 %), and in ``hilgate sim`` by z-tests where it is random.  Bands that do not overlap and modulations
the receiver does not decode are refused, and traced with that cause."""

import json
import math
import random
import subprocess
import sys
import textwrap

import pytest

import textbook_acoustics as tb
from hilgate.models.medium import Channel
from hilgate.models.physical import Acoustic, Environment, PhysicalErrorModel
from hilgate.scene import load_scene_text
from hilgate.sim.budget import link_budget
from netkit import Net

Z_MAX = 3.5
"""Each z-test below compares k lost of n frames with the PER p the textbook gives: k is binomial
(one independent draw per arrival), so z = (k − np)/√(np(1 − p)) is standard normal to well within
the bound (np(1 − p) ≥ 500 here).  P(|z| > 3.5) = 4.7e-4 per test, 1.4e-3 for the three random cases
together (Bonferroni): a correct model fails by chance once in ~700 seeds, while a PER off by 0.03
at n = 4000 and p = 0.5 (a few tenths of a dB of SNR) gives |z| > 3.5 about half the time, and the
bugs of issue 32 (tens of dB, the wrong modulation) every time."""


def scene_text(tx: str, rx: str, d: float, flows: str = "") -> str:
    return textwrap.dedent(f"""\
    name: mixed
    channels: {{ac: {{speed_mps: 1500}}}}
    vehicles:
      a: {{pose: {{static: [0, 0, 0]}}}}
      b: {{pose: {{static: [{d!r}, 0, 0]}}}}
    links:
      tx: {{vehicle: a, address: 1, {tx}}}
      rx: {{vehicle: b, address: 2, {rx}}}
    """) + flows


def row(tx: str, rx: str, d: float, size: int = 64):
    scene = load_scene_text(scene_text(tx, rx, d), "mixed.yaml")
    rows = {(r.src, r.dst): r for r in link_budget(scene, frame_bytes=size)}
    return rows[("tx", "rx")]


PRESET_18_34 = tb.Front(18, 34, 148, bitrate=13900)
PRESET_7_17 = tb.Front(7, 17, 141, bitrate=1900)

# (what differs, sender's keys, receiver's keys, distance m, frame bytes, textbook sender, receiver, water)
EXACT = [
    ("issue 32: expression sender at AT!L0, physical receiver at AT!L3",
     "model: evologics-s2cr-18-34",
     "model: evologics-s2cr-18-34, error: {kind: physical}, acoustic: {level: 3}",
     2000.0, 64, PRESET_18_34, tb.Front(18, 34, 148, level=3, bitrate=13900), tb.Water()),
    ("sender at AT!L2, receiver at AT!L0, both physical",
     "model: evologics-s2cr-18-34, error: {kind: physical}, acoustic: {level: 2}",
     "model: evologics-s2cr-18-34, error: {kind: physical}",
     2250.0, 64, tb.Front(18, 34, 148, level=2, bitrate=13900), PRESET_18_34, tb.Water()),
    ("a 1000 bit/s sender heard by a link set to 4000",
     "bitrate_bps: 1000, acoustic: {band_khz: [20, 24], source_level_db: 128}",
     "bitrate_bps: 4000, acoustic: {band_khz: [20, 24], source_level_db: 150}, error: {kind: physical}",
     3100.0, 32, tb.Front(20, 24, 128, bitrate=1000), tb.Front(20, 24, 150, bitrate=4000), tb.Water()),
    ("non-coherent BFSK sender, BPSK receiver that decodes BFSK too, Francois-Garrison",
     "model: evologics-s2cr-7-17, acoustic: {modulation: bfsk}",
     "model: evologics-s2cr-7-17, acoustic: {decodes: [bfsk]}, "
     "error: {kind: physical, absorption: francois-garrison, temperature_c: 4, salinity_ppt: 30, depth_m: 1000, "
     "ph: 7.9}",
     8000.0, 48, tb.Front(7, 17, 141, modulation="bfsk", bitrate=1900), PRESET_7_17,
     tb.Water(absorption="francois-garrison", t=4, s=30, depth=1000, ph=7.9)),
    ("bands partly overlap: receiver 25-40 kHz hears 25-34 of an 18-34 sender",
     "model: evologics-s2cr-18-34, error: {kind: physical}",
     "bitrate_bps: 9000, acoustic: {band_khz: [25, 40], source_level_db: 150}, error: {kind: physical, shipping: 0.2}",
     2900.0, 64, PRESET_18_34, tb.Front(25, 40, 150, bitrate=9000), tb.Water(shipping=0.2)),
    ("receiver's band inside the sender's, noise at the band centre, wind and a floor",
     "model: evologics-s2cr-7-17",
     "model: evologics-s2cr-7-17, acoustic: {band_khz: [10, 14]}, "
     "error: {kind: physical, noise_band: centre, wind_mps: 6, noise_floor_db: 45, spreading: 1.2}",
     3300.0, 64, PRESET_7_17, tb.Front(10, 14, 141, bitrate=1900),
     tb.Water(noise_band="centre", wind=6, floor_db=45, k=1.2)),
    ("sender's band inside the receiver's, coded QPSK heard by a coherent-BFSK receiver that decodes QPSK",
     "bitrate_bps: 6000, acoustic: {band_khz: [22, 30], source_level_db: 142, modulation: qpsk, coding_gain_db: 4}",
     "model: evologics-s2cr-18-34, acoustic: {modulation: bfsk-coherent, decodes: [qpsk], coding_gain_db: 9}, "
     "error: {kind: physical, absorption: francois-garrison, temperature_c: 25, spreading: 1.8}",
     3900.0, 100, tb.Front(22, 30, 142, modulation="qpsk", gain_db=4, bitrate=6000), PRESET_18_34,
     tb.Water(absorption="francois-garrison", t=25, k=1.8)),
    ("physical sender heard by a receiver at 0.5 m: the 1 m clamp of transmission loss",
     "model: evologics-s2cr-18-34, error: {kind: physical}, acoustic: {level: 3}",
     "model: evologics-s2cr-18-34, error: {kind: physical}",
     0.5, 64, tb.Front(18, 34, 148, level=3, bitrate=13900), PRESET_18_34, tb.Water()),
]


@pytest.mark.parametrize("what,tx,rx,d,size,tb_tx,tb_rx,water", EXACT, ids=[case[0] for case in EXACT])
def test_check_agrees_with_the_textbook_on_mixed_pairs(what, tx, rx, d, size, tb_tx, tb_rx, water):
    got = row(tx, rx, d, size)
    snr = tb.snr_db(d, tb_tx, tb_rx, water)
    per = tb.per(d, size, tb_tx, tb_rx, water)
    assert got.refused is None
    assert got.snr_db == pytest.approx(snr, abs=0.1)
    assert got.per == pytest.approx(per, rel=0.01, abs=1e-300)
    for level, found in ((0.1, got.d_per_01), (0.9, got.d_per_09)):  # within the sender's range, else None
        expected = tb.distance_for(level, size, tb_tx, tb_rx, water)
        if found is None:
            assert expected > got.range_m[1] - 0.5
        else:
            assert found == pytest.approx(expected, abs=0.5)


def test_the_cases_span_the_per():
    """The exact cases are not all at PER 0 or 1, where agreement would say little."""
    pers = [tb.per(d, size, a, b, w) for _, _, _, d, size, a, b, w in EXACT]
    assert sum(1e-4 < p < 0.99 for p in pers) >= 5, pers


def test_issue_32_figures():
    """The issue's example: the sender's own level (AT!L0) applies, not the receiver's AT!L3: SNR
    20.96 dB and PER 5e-62, not 1.0 dB and PER 1."""
    got = row(*EXACT[0][1:4])
    assert got.snr_db == pytest.approx(20.96, abs=0.01) and got.per == pytest.approx(5.35e-62, rel=0.01)


def test_an_expression_receiver_keeps_its_expression_from_a_physical_sender():
    """The receiver's error model decides the kind of loss: its expression, whatever the sender's."""
    got = row("model: evologics-s2cr-18-34, error: {kind: physical}, acoustic: {level: 3}",
              "model: evologics-s2cr-18-34, error: {unit: bit, expr: \"2e-5\"}", 3000.0, 64)
    assert got.refused is None and got.snr_db is None
    assert got.per == pytest.approx(1 - (1 - 2e-5) ** (8 * 64), rel=1e-9)


@pytest.mark.parametrize("tx,rx,cause", [
    ("model: evologics-s2cr-48-78", "model: evologics-s2cr-7-17, error: {kind: physical}", "band"),
    ("model: evologics-s2cr-48-78, error: {kind: physical}", "model: evologics-s2cr-7-17", "band"),  # expr rx
    ("model: evologics-s2cr-18-34, acoustic: {band_khz: [10, 18]}", "model: evologics-s2cr-18-34", "band"),  # touch
    ("model: evologics-s2cr-7-17, acoustic: {modulation: bfsk}", "model: evologics-s2cr-7-17, error: {kind: physical}",
     "modulation"),
    ("model: evologics-s2cr-7-17, acoustic: {modulation: qpsk}",
     "model: evologics-s2cr-7-17, acoustic: {decodes: [bfsk]}", "modulation"),
])
def test_refused_pairs(tx, rx, cause):
    """Bands that do not overlap (touching is not overlapping) and a modulation the receiver does not
    decode: PER 1 and the cause, whatever either end's error model (the issue's 48/78 sender was heard
    by a 7/17 receiver 3 km away at SNR 17.3 dB)."""
    got = row(tx, rx, 3000.0)
    assert (got.refused, got.per, got.snr_db, got.d_per_01, got.d_per_09) == (cause, 1.0, None, None, None)


def test_check_prints_the_senders_level_and_the_refusal(tmp_path):
    text = scene_text("model: evologics-s2cr-18-34",
                      "model: evologics-s2cr-18-34, error: {kind: physical}, acoustic: {level: 3}", 2000.0)
    text = text.replace("links:\n", "links:\n  far: {vehicle: b, address: 3, model: evologics-s2cr-48-78, "
                                    "error: {kind: physical}}\n")
    path = tmp_path / "mixed.yaml"
    path.write_text(text)
    result = subprocess.run([sys.executable, "-m", "hilgate", "check", str(path)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    lines = {line.split("  ")[0]: line.split() for line in result.stdout.splitlines() if " -> " in line}
    assert lines["tx -> rx"][3:7] == ["64", "2000.0", "21.0", "5.35e-62"]
    assert lines["tx -> far"][3:] == ["64", "2000.0", "-", "1", "(band)", "-", "-"]


# -- in simulation ---------------------------------------------------------------------------------------

def simulate(tmp_path, text: str, seed: int = 1, until: float | None = None) -> tuple[dict, list[dict]]:
    """``hilgate sim`` as a user runs it: the summary and the trace."""
    path, summary, trace = tmp_path / "scene.yaml", tmp_path / "summary.json", tmp_path / "trace.jsonl"
    path.write_text(text)
    args = [sys.executable, "-m", "hilgate", "sim", str(path), "--seed", str(seed), "--summary", str(summary),
            "--trace", str(trace), "-q"]
    if until is not None:
        args += ["--until", repr(until)]
    result = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    events = [json.loads(line) for line in trace.read_text().splitlines()]
    return json.loads(summary.read_text()), events


def test_issue_32_in_simulation(tmp_path):
    """2 000 frames from an expression sender at AT!L0 to a physical receiver at AT!L3, 2 km away:
    PER 5e-62, so none is lost (all 2 000 were before)."""
    flows = "flows:\n  - {from: tx, to: rx, size_bytes: 64, interval_s: 0.05, stop_s: 99.99}\n"
    summary, _ = simulate(tmp_path, scene_text(*EXACT[0][1:4]) + flows, until=110)
    flow = summary["flows"][0]
    assert flow["tx_packets"] == 2000 and flow["rx_packets"] == 2000, flow


def test_refused_frames_are_traced_with_their_cause(tmp_path):
    """A 48/78 kHz sender 3 km from a 7/17 kHz receiver: every frame for it is an ``err`` cause
    ``band`` (and it hears nothing else of them); a BFSK sender to a BPSK receiver: cause
    ``modulation``.  The summary counts them under their cause."""
    text = scene_text("model: evologics-s2cr-48-78, range_m: [0, 5000]",
                      "model: evologics-s2cr-7-17, error: {kind: physical}", 3000.0)
    text = text.replace("links:\n", "links:\n  fsk: {vehicle: a, address: 3, model: evologics-s2cr-7-17, "
                                    "acoustic: {modulation: bfsk}}\n")
    flows = ("flows:\n  - {from: tx, to: rx, size_bytes: 32, interval_s: 1, stop_s: 9.5}\n"
             "  - {from: fsk, to: rx, size_bytes: 32, interval_s: 1, start_s: 0.5, stop_s: 9.9}\n")
    summary, events = simulate(tmp_path, text + flows, until=20)
    band, modulation = summary["flows"]
    assert (band["tx_packets"], band["rx_packets"], band["lost"]) == (10, 0, {"prop": 0, "col": 0, "mult": 0,
                                                                              "range": 0, "band": 10})
    assert (modulation["tx_packets"], modulation["rx_packets"], modulation["lost"]) == (
        10, 0, {"prop": 0, "col": 0, "mult": 0, "range": 0, "modulation": 10})
    errors = [(e["src"], e["cause"]) for e in events if e["ev"] == "err" and e["link"] == "rx"]
    assert sorted(set(errors)) == [("fsk", "modulation"), ("tx", "band")] and len(errors) == 20


def random_case(rng: random.Random):
    """Two front ends that differ in everything (bands that partly overlap, levels, rates, modulations
    the receiver decodes, coding gains), either error kind for the sender, random water."""
    modulations = ["bpsk", "qpsk", "bfsk", "bfsk-coherent"]
    while True:
        rx_low, rx_width = rng.uniform(6, 50), rng.uniform(5, 25)
        tx_low, tx_width = rx_low + rng.uniform(-0.6, 0.6) * rx_width, rng.uniform(5, 25)
        if min(rx_low + rx_width, tx_low + tx_width) - max(rx_low, tx_low) > 1.0:
            break
    tx = tb.Front(round(tx_low, 3), round(tx_low + tx_width, 3), round(rng.uniform(135, 165), 2), rng.randrange(4),
                  rng.choice(modulations), round(rng.uniform(0, 6), 2), round(rng.uniform(500, 12000)))
    rx = tb.Front(round(rx_low, 3), round(rx_low + rx_width, 3), round(rng.uniform(135, 165), 2), rng.randrange(4),
                  rng.choice(modulations), round(rng.uniform(0, 6), 2), round(rng.uniform(500, 12000)))
    water = tb.Water(absorption=rng.choice(["thorp", "francois-garrison"]), k=round(rng.uniform(1, 2), 3),
                     shipping=round(rng.random(), 3), wind=round(rng.uniform(0, 10), 2),
                     floor_db=rng.choice([None, round(rng.uniform(30, 60), 1)]),
                     noise_band=rng.choice(["integral", "centre"]), t=round(rng.uniform(0, 30), 1),
                     s=round(rng.uniform(30, 40), 1), depth=round(rng.uniform(0, 2000)), ph=round(rng.uniform(7.7, 8.3), 2))
    sender_error = rng.choice(["{unit: packet, expr: \"0\"}", "{kind: physical, spreading: 2}"])
    return tx, rx, water, sender_error, rng.uniform(0.2, 0.8), rng.randrange(16, 129)


def front_keys(front: tb.Front, decodes: str = "") -> str:
    return (f"bitrate_bps: {front.bitrate}, acoustic: {{band_khz: [{front.low_khz}, {front.high_khz}], "
            f"source_level_db: {front.sl_db}, level: {front.level}, modulation: {front.modulation}, "
            f"coding_gain_db: {front.gain_db}{decodes}}}")


@pytest.mark.parametrize("case", [1, 2, 3])
def test_random_mixed_pair_in_simulation_matches_the_textbook_per(case, tmp_path):
    rng = random.Random(f"issue32/{case}")
    tx, rx, water, sender_error, target, size = random_case(rng)
    d = tb.distance_for(target, size, tx, rx, water)
    p = tb.per(d, size, tx, rx, water)
    floor = "" if water.floor_db is None else f", noise_floor_db: {water.floor_db}"
    env = (f"{{kind: physical, absorption: {water.absorption}, spreading: {water.k}, shipping: {water.shipping}, "
           f"wind_mps: {water.wind}, noise_band: {water.noise_band}, temperature_c: {water.t}, "
           f"salinity_ppt: {water.s}, depth_m: {water.depth}, ph: {water.ph}{floor}}}")
    decodes = "" if rx.modulation == tx.modulation else f", decodes: [{tx.modulation}]"
    n = 4000
    interval = 8 * size / tx.bitrate + 0.01
    flows = f"flows:\n  - {{from: tx, to: rx, size_bytes: {size}, interval_s: {interval!r}, stop_s: {(n - 0.5) * interval!r}}}\n"
    text = scene_text(f"{front_keys(tx)}, error: {sender_error}", f"{front_keys(rx, decodes)}, error: {env}", d)
    summary, _ = simulate(tmp_path, text + flows, seed=case, until=n * interval + d / 1500 + 5)
    flow = summary["flows"][0]
    k = flow["lost"]["prop"]
    assert flow["tx_packets"] == n and flow["rx_packets"] + k == n, flow
    z = (k - n * p) / math.sqrt(n * p * (1 - p))
    assert abs(z) <= Z_MAX, (tx, rx, water, d, p, k / n, z)


# -- the cost stays per pair ---------------------------------------------------------------------------

def test_a_path_is_bound_once_per_pair_not_per_frame(monkeypatch):
    """The medium binds the receiver's model to the sender when it lists the pair: 200 frames each way
    between two moving-free modems cost two bindings, and every arrival uses the bound model."""
    import hilgate.models.propagation as propagation

    calls = []
    real = propagation.bind_path
    monkeypatch.setattr(propagation, "bind_path", lambda s, r: calls.append((s, r)) or real(s, r))
    loud = Acoustic((7.0, 17.0), 141.0)
    quiet = Acoustic((7.0, 17.0), 141.0, level=3, modulation="qpsk", decodes=("bpsk",))
    env = Environment()
    net = Net(Channel("ac", 1500.0), seed=2)
    net.modem("a", (0, 0, 0), bitrate_bps=1900.0, error=PhysicalErrorModel(env, loud, 1900.0), acoustic=loud)
    net.modem("b", (3000, 0, 0), bitrate_bps=500.0, acoustic=quiet)
    for i in range(200):
        net.send("a", "b", 20, at=i * 2.0)
        net.send("b", "a", 20, at=i * 2.0 + 1.0)
    net.run()
    assert len(calls) == 2
    assert len(net.of("rx", "b")) == 200  # b's error model is none: nothing lost on a -> b
    assert {e[4] for e in net.of("err", "a")} == {"modulation"} and len(net.of("err", "a")) == 200


def test_an_undecodable_sender_still_interferes_under_sinr():
    """With ``collisions: sinr`` a sender the receiver cannot decode (BFSK at a BPSK receiver) adds its
    received power to the interference of what it overlaps: a strong one 100 m away spoils a weak
    decodable frame from 1000 m, and its own frame ends as ``modulation``, not captured."""
    env = Environment(collisions="sinr", capture_db=10.0)
    bpsk = Acoustic((18.0, 34.0), 160.0)
    bfsk = Acoustic((18.0, 34.0), 160.0, modulation="bfsk")
    outcomes = {}
    for strong_modulation in (bpsk, bfsk):
        net = Net(Channel("ac", 1500.0), seed=3)
        net.modem("r", (0, 0, 0), bitrate_bps=8000.0, error=PhysicalErrorModel(env, bpsk, 8000.0), acoustic=bpsk)
        net.modem("strong", (100, 0, 0), bitrate_bps=8000.0, acoustic=strong_modulation)
        net.modem("weak", (0, 1000, 0), bitrate_bps=8000.0, acoustic=bpsk)
        strong = net.send("strong", "r", 100, at=1.0 - 100 / 1500.0)
        weak = net.send("weak", "r", 100, at=1.0 - 1000 / 1500.0 + 0.05)
        net.run()
        names = {strong.id: "strong", weak.id: "weak"}
        got = {names[e[3]]: "rx" for e in net.of("rx", "r")}
        got.update({names[e[3]]: e[4] for e in net.of("err", "r")})
        outcomes[strong_modulation.modulation] = got
    assert outcomes == {"bpsk": {"strong": "rx", "weak": "mult"}, "bfsk": {"strong": "modulation", "weak": "mult"}}
