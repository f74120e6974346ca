"""scenes/intervention.yaml under the three MAC settings: what each protocol is for, from the summary."""

import io
import json
import os

import pytest

from hilgate.scene import load_scene
from hilgate.sim.simulate import simulate

SCENE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes", "intervention.yaml")


def run(protocol):
    trace = io.StringIO()
    scene = load_scene(SCENE, [f"links.*.mac.protocol={protocol}"])
    summary = simulate(scene, until=300, trace=trace)
    flows = {(f["from"], f["to"]): f for f in summary["flows"]}
    kinds = {json.loads(line).get("kind") for line in trace.getvalue().splitlines()}
    return flows, kinds


@pytest.fixture(scope="module")
def results():
    return {protocol: run(protocol) for protocol in ("none", "cs-aloha", "s-fama")}


IMAGES = [(f"explorer{i}_ac", "buoy_ac") for i in range(1, 5)]


def test_control_frames_only_where_the_protocol_sends_them(results):
    assert results["none"][1] == {None}
    assert results["cs-aloha"][1] == {None, "ack"}
    assert results["s-fama"][1] == {None, "rts", "cts", "ack"}


def test_sfama_images_never_collide_and_waste_little(results):
    flows = results["s-fama"][0]
    assert all(flows[k]["lost"]["col"] == 0 and flows[k]["lost"]["mult"] == 0 for k in IMAGES)
    assert all(flows[k]["efficiency"] > 0.85 for k in IMAGES if flows[k]["rx_packets"])
    none = results["none"][0]
    assert sum(flows[k]["rx_packets"] for k in IMAGES) > sum(none[k]["rx_packets"] for k in IMAGES)


def test_csaloha_carries_the_small_frequent_rf_poses_best(results):
    pose = ("leader_rf", "follower_rf")
    delivered = {p: results[p][0][pose]["rx_packets"] for p in results}
    assert delivered["cs-aloha"] > 1.5 * delivered["none"]
    assert delivered["cs-aloha"] > 1.5 * delivered["s-fama"]
    # the ACKs are on-air bytes of the flow: efficiency below 1 even when nothing is lost
    assert results["cs-aloha"][0][pose]["efficiency"] < 20 / 25 + 1e-9


def test_without_a_mac_the_support_commands_mostly_collide(results):
    support = results["none"][0][("support_rf", "leader_rf")]
    assert support["lost"]["col"] > support["rx_packets"]
