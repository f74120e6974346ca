"""The paper's first experiment, in virtual time: the qualitative facts its figures show."""

import io
import json
import math
import os

import pytest

from hilgate.scene import load_scene
from hilgate.sim.simulate import simulate

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")
BOTH = (37.0, 58.0)  # rov1 transmits too


def run(name):
    trace = io.StringIO()
    summary = simulate(load_scene(os.path.join(SCENES, name)), trace=trace)
    return summary, [json.loads(line) for line in trace.getvalue().splitlines()]


def distance_at(events, t):
    poses = {}
    for e in events:
        if e["ev"] == "pose" and e["t"] <= t:
            poses[e["vehicle"]] = e["position"]
    return math.dist(poses["rov0"], poses["rov1"])


@pytest.fixture(scope="module")
def rf():
    return run("paper-exp1-rf.yaml")


def test_losses_by_attenuation_rise_with_distance_beyond_4_m(rf):
    _, events = rf
    sent = [e for e in events if e["ev"] == "tx" and e["link"] == "rov0_rf" and e["t"] < BOTH[0]]
    prop = {e["pkt"] for e in events if e["ev"] == "err" and e.get("cause") == "prop"}
    near = [e for e in sent if distance_at(events, e["t"]) < 3.0]
    far = [e for e in sent if distance_at(events, e["t"]) > 5.0]
    assert len(near) > 150 and len(far) > 20  # under 3 m until 19.8 s; over 5 m from 28 s to 34 s
    assert sum(e["pkt"] in prop for e in near) <= 2  # PER 3e-4 at 3 m
    assert sum(e["pkt"] in prop for e in far) / len(far) > 0.5  # PER 0.6 at 5 m, 0.99 at 5.8 m


def test_collisions_only_while_both_transmit_and_some_with_errors_too(rf):
    summary, events = rf
    collided = [e for e in events if e["ev"] == "err" and e.get("cause") in ("col", "mult")]
    assert len(collided) > 50
    assert all(BOTH[0] <= e["t"] <= BOTH[1] + 2.0 for e in collided)
    assert sum(f["lost"]["mult"] for f in summary["flows"]) > 0


def test_the_fifo_fills_only_while_both_transmit(rf):
    _, events = rf
    waiting = [e for e in events if e["ev"] in ("enq", "tx") and e.get("fifo_bytes", 0) > 20]
    assert waiting and all(BOTH[0] <= e["t"] <= BOTH[1] + 3.0 for e in waiting)
    assert max(e["fifo_bytes"] for e in waiting) >= 100


def test_acoustic_delay_follows_the_distance():
    _, events = run("paper-exp1-acoustic.yaml")
    enq = {e["pkt"]: e["t"] for e in events if e["ev"] == "enq"}
    tx = {e["pkt"]: e["t"] for e in events if e["ev"] == "tx"}
    for e in events:
        if e["ev"] == "rx" and e["link"] == "rov1_ac" and e["t"] < BOTH[0]:
            d = distance_at(events, tx[e["pkt"]])  # pose samples every 0.25 s: within 6 cm of the truth
            assert e["t"] - enq[e["pkt"]] == pytest.approx(0.001 + 20 * 8 / 1900 + d / 1500, abs=0.00005)
