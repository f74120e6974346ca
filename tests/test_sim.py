"""``hilgate sim`` end to end: flows, determinism, the trace and summary formats of DESIGN.md."""

import io
import json
import os
import subprocess
import sys

import pytest

from hilgate.scene import load_scene_text
from hilgate.sim.simulate import simulate

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO = os.path.join(REPO, "scenes", "demo.yaml")

TWO = """\
name: pair
seed: 5
duration_s: 10
channels: {ac: {speed_mps: 1500}}
vehicles:
  a: {pose: {static: [0, 0, 0]}}
  b: {pose: {static: [150, 0, 0]}}
links:
  la: {vehicle: a, bitrate_bps: 1000, tx_delay_s: 0.01, fifo_bytes: 100}
  lb: {vehicle: b, bitrate_bps: 1000, rx_delay_s: 0.02}
flows:
  - {from: la, to: lb, size_bytes: 10, interval_s: 0.5, start_s: 1, stop_s: 3}
"""

TRACE_KEYS = ["t", "ev", "link", "pkt", "src", "dst", "size", "fifo_bytes"]


def run(text, **kwargs):
    trace = io.StringIO()
    summary = simulate(load_scene_text(text), trace=trace, **kwargs)
    return summary, [json.loads(line) for line in trace.getvalue().splitlines()], trace.getvalue()


def test_interval_flow_sends_at_start_plus_k_interval_before_stop():
    summary, trace, _ = run(TWO)
    enq = [e["t"] for e in trace if e["ev"] == "enq"]
    assert enq == [1.0, 1.5, 2.0, 2.5]
    # every delay is exactly tx_delay + T + tau + rx_delay = 0.01 + 0.08 + 0.1 + 0.02
    [flow] = summary["flows"]
    assert flow["delay_mean_s"] == pytest.approx(0.21, abs=1e-9)
    assert flow["delay_p50_s"] == pytest.approx(0.21, abs=1e-9)
    assert flow["delay_p95_s"] == pytest.approx(0.21, abs=1e-9)
    assert flow["jitter_s"] == pytest.approx(0.0, abs=1e-9)
    assert (flow["offered"], flow["tx_packets"], flow["rx_packets"], flow["rx_bytes"]) == (4, 4, 4, 40)
    assert flow["throughput_Bps"] == pytest.approx(40 / 2.0)  # over the flow's active 2 s
    assert flow["efficiency"] == 1.0


def test_trace_lines_follow_the_design_format():
    _, events, text = run(TWO)
    poses = [e for e in events if e["ev"] == "pose"]
    trace = [e for e in events if e["ev"] != "pose"]
    # once a second, every vehicle's position (for the report's distance plots)
    assert poses[:2] == [{"t": 0.0, "ev": "pose", "vehicle": "a", "position": [0.0, 0.0, 0.0]},
                         {"t": 0.0, "ev": "pose", "vehicle": "b", "position": [150.0, 0.0, 0.0]}]
    assert len(poses) == 2 * 11
    for event in trace:
        keys = [k for k in event if k != "cause"]
        assert keys == TRACE_KEYS
        assert ("cause" in event) == (event["ev"] in ("drop", "err"))
    first_tx = next(e for e in trace if e["ev"] == "tx")
    assert first_tx == {"t": 1.01, "ev": "tx", "link": "la", "pkt": 1, "src": "la", "dst": "lb", "size": 10,
                        "fifo_bytes": 0}
    first_rx = next(e for e in trace if e["ev"] == "rx")
    assert first_rx["link"] == "lb" and first_rx["t"] == pytest.approx(1.21, abs=1e-9)
    assert len({e["pkt"] for e in trace}) == 4


def test_fifo_drops_appear_in_trace_and_summary():
    text = TWO.replace("interval_s: 0.5, start_s: 1, stop_s: 3", "interval_s: 0.001, start_s: 0, stop_s: 0.05")
    summary, trace, _ = run(text)
    drops = [e for e in trace if e["ev"] == "drop"]
    flow = summary["flows"][0]
    assert flow["offered"] == 50
    assert flow["fifo_drops"] == len(drops) > 0
    assert all(e["cause"] == "fifo" and e["fifo_bytes"] == 100 for e in drops)
    assert summary["links"][0]["fifo_drops"] == len(drops)
    assert summary["links"][0]["fifo_peak_bytes"] == 100


def test_summary_has_exactly_the_design_fields():
    summary, _, _ = run(TWO)
    assert list(summary) == ["scene", "seed", "sim_time_s", "wall_time_s", "flows", "links"]
    assert list(summary["flows"][0]) == [
        "from", "to", "offered", "fifo_drops", "tx_packets", "tx_bytes", "rx_packets", "rx_bytes", "lost",
        "throughput_Bps", "efficiency", "delay_mean_s", "delay_p50_s", "delay_p95_s", "jitter_s"]
    assert list(summary["flows"][0]["lost"]) == ["prop", "col", "mult", "range"]
    # DESIGN.md's link fields first; then (issue 24) the backend and one segment per backend period, the
    # same as the daemon's summary writes (here one simulated period over the whole run)
    link = summary["links"][0]
    assert list(link) == ["id", "tx_packets", "rx_packets", "fifo_drops", "fifo_peak_bytes", "backend", "segments"]
    assert link["backend"] == "sim" and link["segments"] == [
        {"backend": "sim", "start_s": 0.0, "end_s": 10, "tx_packets": link["tx_packets"],
         "rx_packets": link["rx_packets"], "drops": link["fifo_drops"], "fifo_peak_bytes": link["fifo_peak_bytes"]}]
    assert summary["scene"] == "pair" and summary["seed"] == 5 and summary["sim_time_s"] == 10


def test_the_same_seed_gives_the_same_trace_byte_for_byte():
    demo = open(DEMO).read()
    _, _, first = run(demo, until=60)
    _, _, second = run(demo, until=60)
    assert first == second and len(first) > 10_000
    _, _, other = run(demo, until=60, seed=99)
    assert other != first


def test_poisson_flow_count_is_within_binomial_bounds():
    text = TWO.replace("interval_s: 0.5, start_s: 1, stop_s: 3", "rate_hz: 2, poisson: true") \
              .replace("duration_s: 10", "duration_s: 2000").replace("fifo_bytes: 100", "fifo_bytes: 100000")
    summary, _, _ = run(text)
    n = summary["flows"][0]["offered"]
    # Poisson(4000): sd = 63.2; 5 sd either way
    assert 4000 - 5 * 63.3 <= n <= 4000 + 5 * 63.3


def test_broadcast_flow_counts_each_receiver():
    text = TWO.replace("to: lb", 'to: "*"').replace(
        "  lb: {vehicle: b, bitrate_bps: 1000, rx_delay_s: 0.02}",
        "  lb: {vehicle: b, bitrate_bps: 1000, rx_delay_s: 0.02}\n  lc: {vehicle: b}")
    summary, trace, _ = run(text)
    flow = summary["flows"][0]
    assert flow["to"] == "*" and flow["tx_packets"] == 4 and flow["rx_packets"] == 8
    assert {e["dst"] for e in trace if e["ev"] != "pose"} == {"*"}


def test_sim_command_prints_the_table_and_writes_trace_and_summary(tmp_path):
    trace, summary = tmp_path / "t.jsonl", tmp_path / "s.json"
    result = subprocess.run(
        [sys.executable, "-m", "hilgate", "sim", DEMO, "--until", "30", "--trace", str(trace), "--summary", str(summary)],
        capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "bluerov_rf -> rov2_rf" in result.stdout and "delay mean" in result.stdout
    data = json.loads(summary.read_text())
    assert data["sim_time_s"] == 30 and data["scene"] == "demo"
    lines = trace.read_text().splitlines()
    assert all(json.loads(line)["t"] <= 30 for line in lines)
    assert result.stderr == ""  # no progress bar when stderr is not a terminal


def test_demo_scene_shows_every_kind_of_outcome():
    summary, trace, _ = run(open(DEMO).read())
    causes = {e.get("cause") for e in trace if e["ev"] == "err"}
    assert {"prop", "col", "range"} <= causes
    assert all(f["offered"] > 0 for f in summary["flows"])
    assert sum(f["rx_packets"] for f in summary["flows"]) > 100


def test_demo_scene_is_true_to_its_comments():
    """The demo's comments: `hilgate sim` runs two minutes; the AUV flies its lawn-mower pattern over and
    over (130 s a round), the second ROV comes back about every 70 s: under `hilgate run` they keep moving."""
    from hilgate.scene.load import load_scene
    from hilgate.sim.pose_sources import build_pose

    text = open(DEMO).read()
    assert "duration_s: two minutes" in text and "130 s a round" in text and "about 70 s a round" in text
    scene = load_scene(DEMO)
    assert scene.duration_s == 120
    auv, rov2 = build_pose(scene.vehicles["auv"]), build_pose(scene.vehicles["rov2"])
    for t in (0.0, 17.5, 60.0, 111.0, 125.0):
        assert auv.position(t + 130) == pytest.approx(auv.position(t))
    assert auv.position(111.0) != pytest.approx(auv.position(125.0))  # still moving past its last row
    assert all(40 <= auv.position(t)[0] <= 50 for t in range(0, 261, 5))
    period = 10 + 5 / 0.25 + 15 + 10 + ((5 ** 2 + 3 ** 2) ** 0.5) / 0.4
    assert 65 <= period <= 75
    assert rov2.position(3.0 + period) == pytest.approx(rov2.position(3.0))
