"""``hilgate fit``: parameters recovered from simulated traces (with 95 % coverage over seeds), what is
left out and why, the matching of real links' frames, and the one-line refusals."""

import math
import subprocess
import sys

import pytest

from hilgate.commands.fitting import FitError, print_fit, run_fit
from hilgate.report.observations import LinkInfo, observations
from hilgate.scene import load_scene
from hilgate.sim.simulate import simulate

A, B = 6e-13, 13.7  # UWSim-NET's S100 fit, the truth the fits must find

SCENE = """\
name: fitme
seed: 1
duration_s: {duration}
channels:
  rf: {{speed_mps: 2.25e7}}
vehicles:
  a: {{pose: {{static: [0, 0, 0]}}}}
  b:
    pose:
      path:
        start: [3.5, 0, 0]
        legs: [{{to: [6, 0, 0], speed_mps: {speed}}}]
links:
  la: {{vehicle: a, channel: rf, model: s100, error: {{unit: bit, expr: "{expr}"}}}}
  lb: {{vehicle: b, channel: rf, model: s100, error: {{unit: bit, expr: "{expr}"}}}}
flows:
  - {{from: la, to: lb, size_bytes: 20, interval_s: 0.25}}
{extra}
"""


def simulated_trace(tmp_path, seed, expr=f"{A} * d^{B}", duration=250, extra="", name="scene.yaml"):
    scene_path = tmp_path / name
    scene_path.write_text(SCENE.format(duration=duration, speed=2.5 / duration, expr=expr, extra=extra))
    trace_path = tmp_path / f"{name}.{seed}.jsonl"
    with open(trace_path, "w", encoding="utf-8") as trace:
        simulate(load_scene(str(scene_path)), seed=seed, trace=trace)
    return str(trace_path), str(scene_path)


def test_power_fit_covers_the_truth_95_percent_of_the_time(tmp_path):
    """40 seeds of 1000 frames each: each seed's 95 % intervals must hold the true a and b about 95 % of
    the time.  With 40 trials the count of misses is Binomial(40, 0.05) if the intervals are right:
    at z = 5 at most 0.05·40 + 5·√(40·0.05·0.95) = 8.9 misses; intervals half as wide as they should
    be would miss 32 % of the time (13 of 40)."""
    seeds = range(1, 41)
    misses = {"a": 0, "b": 0}
    estimates = []
    for seed in seeds:
        trace, scene = simulated_trace(tmp_path, seed)
        result = run_fit(trace, scene, "power", simulated=True)
        a, a_low, a_high = result.params["a"]
        b, b_low, b_high = result.params["b"]
        misses["a"] += not a_low <= A <= a_high
        misses["b"] += not b_low <= B <= b_high
        estimates.append(b)
    bound = 0.05 * len(seeds) + 5 * math.sqrt(len(seeds) * 0.05 * 0.95)
    assert misses["a"] <= bound and misses["b"] <= bound, misses
    assert abs(sum(estimates) / len(estimates) - B) < 0.3  # and no visible bias


def test_fit_output_is_a_block_the_scene_takes(tmp_path):
    trace, scene = simulated_trace(tmp_path, 7)
    result = run_fit(trace, scene, "power", simulated=True)
    assert result.block.startswith("error: {unit: bit, expr: ")
    # paste it into the scene: it loads, and it is the fitted curve
    fitted = tmp_path / "fitted.yaml"
    fitted.write_text(open(scene).read().replace(f'error: {{unit: bit, expr: "{A} * d^{B}"}}',
                                                 result.block))
    model = load_scene(str(fitted)).links["lb"].params.error
    a, b = result.params["a"][0], result.params["b"][0]
    assert model.per(5.0, 20) == pytest.approx(1 - (1 - a * 5.0 ** b) ** 160, rel=1e-4)
    assert result.data.excluded == {} and len(result.data.frames) == 1000


def test_logistic_fit_covers_its_parameters(tmp_path):
    """The logistic form over 20 seeds: misses of the 95 % intervals stay within z = 5 of Binomial(20, 0.05)."""
    trace, scene = simulated_trace(tmp_path, 1, expr="0")
    text = open(scene).read().replace('error: {unit: bit, expr: "0"}',
                                      'error: {unit: packet, expr: "1 / (1 + exp(-(-30 + 6 * d)))"}')
    open(scene, "w").write(text)
    misses = 0
    for seed in range(1, 21):
        with open(trace, "w", encoding="utf-8") as handle:
            simulate(load_scene(scene), seed=seed, trace=handle)
        result = run_fit(trace, scene, "logistic", simulated=True)
        (_, b0_low, b0_high), (_, b1_low, b1_high) = result.params["beta0"], result.params["beta1"]
        misses += not (b0_low <= -30 <= b0_high and b1_low <= 6 <= b1_high)
    assert misses <= 0.1 * 20 + 5 * math.sqrt(20 * 0.1 * 0.9)  # either of two 95 % intervals: ≤ 10 % misses
    assert result.block.startswith('error: {unit: packet, expr: "1 / (1 + exp(-(')


def test_collisions_and_fifo_drops_are_left_out_and_counted(tmp_path):
    extra = """\
  - {from: la, to: lb, size_bytes: 20, interval_s: 0.25, start_s: 0.01}
  - {from: la, to: lb, size_bytes: 20, interval_s: 0.5, start_s: 0.02}
  - {from: lb, to: la, size_bytes: 20, interval_s: 1.37}
"""
    trace, scene = simulated_trace(tmp_path, 2, extra=extra)
    text = open(scene).read().replace('la: {vehicle: a, channel: rf, model: s100,',
                                      'la: {vehicle: a, channel: rf, model: s100, fifo_bytes: 30,')
    open(scene, "w").write(text)
    with open(trace, "w", encoding="utf-8") as handle:
        simulate(load_scene(scene), seed=2, trace=handle)
    result = run_fit(trace, scene, "power", simulated=True, links=["lb"])
    lines = open(trace).read().splitlines()
    at_lb = [line for line in lines if '"ev": "err"' in line and '"link": "lb"' in line]
    collisions = sum(1 for line in at_lb if '"cause": "col"' in line or '"cause": "mult"' in line)
    fifo = sum(1 for line in lines if '"ev": "drop"' in line and '"cause": "fifo"' in line)
    assert collisions > 0 and fifo > 0
    assert result.data.excluded == {"collision": collisions, "fifo": fifo}
    assert {o.dst for o in result.data.frames} == {"lb"}
    heard = sum(1 for line in lines if '"link": "lb"' in line and ('"ev": "rx"' in line or '"cause": "prop"' in line))
    assert len(result.data.frames) == heard


def test_refuses_a_simulated_trace_unless_told(tmp_path):
    trace, scene = simulated_trace(tmp_path, 1, duration=20)
    with pytest.raises(FitError, match="no frames sent by real links.*--simulated"):
        run_fit(trace, scene, "power")


def test_refuses_a_trace_without_poses(tmp_path):
    trace, scene = simulated_trace(tmp_path, 1, duration=20, extra="trace: {poses_s: 0}")
    with pytest.raises(FitError, match="no pose samples"):
        run_fit(trace, scene, "power", simulated=True)


def test_cli_refusal_is_one_line_and_exit_2(tmp_path):
    trace, scene = simulated_trace(tmp_path, 1, duration=20)
    result = subprocess.run([sys.executable, "-m", "hilgate", "fit", trace, "--scene", scene], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("hilgate: fit: the trace has no frames")


def test_cli_prints_the_fit(tmp_path):
    trace, scene = simulated_trace(tmp_path, 5)
    result = subprocess.run([sys.executable, "-m", "hilgate", "fit", trace, "--scene", scene, "--simulated"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("1000 frames (") and "heard or missed by lb; left out: none" in lines[0]
    assert any(line.startswith('error: {unit: bit, expr: "') for line in lines)
    table = lines[lines.index(next(l for l in lines if l.lstrip().startswith("d from"))) + 1:]
    assert len(table) == 10 and sum(int(row.split()[2]) for row in table) == 1000


# -- real links: frames matched by time, size and address -----------------------------------------------

REAL_LINKS = {
    "ea": LinkInfo("a", "evologics", 1, "ac", "ac"),
    "eb": LinkInfo("b", "evologics", 2, "ac", "ac"),
    "sim": LinkInfo("b", "sim", 3, "ac", "ac"),
}


def real_trace():
    """Lines as drivers/evologics.py writes them (tx with the destination address; rx with the source
    address, RSSI and integrity), with the daemon's pose samples."""
    events = [{"t": 0.0, "ev": "run", "run": "r1", "scene": "x", "path": "/nonexistent"}]
    for t in range(0, 41, 2):
        events.append({"t": float(t), "ev": "pose", "vehicle": "a", "position": [0.0, 0.0, 0.0]})
        events.append({"t": float(t), "ev": "pose", "vehicle": "b", "position": [10.0 + t, 0.0, 0.0]})
    for i in range(20):
        t = 1.0 + 2 * i
        events.append({"t": t, "ev": "tx", "link": "ea", "dst": 2, "size": 30})
        if i % 3:  # every third frame lost
            events.append({"t": t + 0.4, "ev": "rx", "link": "eb", "src": 1, "dst": 2, "size": 30,
                           "kind": "recvim", "rssi": -60 - i, "integrity": 120})
    events.append({"t": 41.0, "ev": "tx", "link": "ea", "dst": 2, "size": 30})
    events.append({"t": 41.2, "ev": "rx", "link": "eb", "src": 7, "dst": 2, "size": 30})  # another sender
    events.append({"t": 41.3, "ev": "rx", "link": "eb", "src": 1, "dst": 2, "size": 31})  # another size
    events.append({"t": 45.0, "ev": "tx", "link": "ea", "dst": 2, "size": 30})  # 5 s after the last pose
    events.append({"t": 45.1, "ev": "rx", "link": "eb", "src": 1, "dst": 2, "size": 30})
    return sorted(events, key=lambda e: e["t"])


def test_real_frames_are_matched_by_time_size_and_source():
    data = observations(real_trace(), REAL_LINKS)
    # the frame at 45 s has no pose within 2 s; the one at 41 s takes the sample at 40 s
    assert len(data.frames) == 21 and data.excluded == {"no pose": 1}
    lost = [o for o in data.frames if not o.delivered]
    # every third frame, and the one at 41 s (what eb heard then came from another address, or was longer)
    assert [round(o.t) for o in lost] == [1 + 2 * i for i in range(20) if i % 3 == 0] + [41]
    second = data.frames[1]
    assert second.delivered and second.rssi == -61 and second.integrity == 120
    assert second.d == pytest.approx(13.0)  # b at 10 + t: the sample at t = 2 and 4 interpolated at 3
    assert data.frames[-1].d == pytest.approx(50.0)


def test_real_trace_is_fitted_without_simulated(tmp_path):
    with pytest.raises(FitError, match="no pose samples"):
        observations([e for e in real_trace() if e["ev"] != "pose"], REAL_LINKS)
    data = observations(real_trace(), REAL_LINKS, receivers={"eb"})
    assert len(data.frames) == 21 and {o.dst for o in data.frames} == {"eb"}
    assert observations(real_trace(), REAL_LINKS, receivers={"ea"}).frames == []


PHYSICAL = """\
name: phys-fit
seed: 1
duration_s: 400
channels: {ac: {speed_mps: 1500}}
vehicles:
  a: {pose: {static: [0, 0, 0]}}
  b:
    pose:
      path:
        start: [1500, 0, 0]
        legs: [{to: [4500, 0, 0], speed_mps: 7.5}]
links:
  la: {vehicle: a, model: evologics-s2cr-18-34, error: {kind: physical, spreading: 1.6}}
  lb: {vehicle: b, model: evologics-s2cr-18-34, error: {kind: physical, spreading: 1.6}}
flows:
  - {from: la, to: lb, size_bytes: 64, interval_s: 0.5}
"""


def test_physical_fit_recovers_the_source_level(tmp_path):
    """Simulated with k = 1.6 and the preset's 148 dB; a simulated trace has no RSSI, so k is held at
    the scene's and the level is fitted: its 95 % interval holds 148 dB (one seed; the interval
    machinery is the one whose coverage the power form checks over 40 seeds)."""
    scene = tmp_path / "phys.yaml"
    scene.write_text(PHYSICAL)
    trace = tmp_path / "phys.jsonl"
    with open(trace, "w", encoding="utf-8") as handle:
        simulate(load_scene(str(scene)), seed=1, trace=handle)
    result = run_fit(str(trace), str(scene), "physical", simulated=True, links=["lb"])
    sl, sl_low, sl_high = result.params["source_level_db"]
    assert sl_low <= 148 <= sl_high and sl_high - sl_low < 2.0, result.params
    assert "spreading" not in result.params
    assert result.block.splitlines()[1].startswith("error: {kind: physical, spreading: 1.600}   # k held at")
    with pytest.raises(FitError, match="--model physical needs"):
        trace2, scene2 = simulated_trace(tmp_path, 1, duration=60)
        run_fit(trace2, scene2, "physical", simulated=True)


def test_spreading_from_rssi():
    """RSSI falling as 15·log10(d) + α·d (k = 1.5) with ±1 dB of noise: the regression finds k."""
    import random

    from hilgate.report.fit import fit_rssi

    rng = random.Random(4)
    alpha = 6.5
    d = [100 + 20 * i for i in range(200)]
    rssi = [-40 - 15 * math.log10(x) - alpha * x / 1000 + rng.gauss(0, 1) for x in d]
    k, se, c, sigma = fit_rssi(d, rssi, alpha)
    assert abs(k - 1.5) <= 5 * se and se < 0.05 and sigma == pytest.approx(1.0, abs=0.15)


def test_plot_draws_the_fit(tmp_path):
    pytest.importorskip("matplotlib")
    from hilgate.commands.fitting import plot_fit

    trace, scene = simulated_trace(tmp_path, 9)
    result = run_fit(trace, scene, "power", simulated=True)
    plot_fit(result, str(tmp_path / "fit.png"))
    assert (tmp_path / "fit.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_real_link_traced_with_link_names_does_not_stop_the_fit():
    """Issue 24: a link's tx traced by the simulated backend (``"dst": "*"`` or a link id) before a swap
    to a real modem made ``fit`` fail on int('*'); names are read as the addresses they stand for."""
    events = real_trace()
    events.insert(1, {"t": 0.5, "ev": "tx", "link": "ea", "dst": "*", "size": 30})   # broadcast: to eb (and sim)
    events.insert(2, {"t": 0.6, "ev": "tx", "link": "ea", "dst": "eb", "size": 30})  # by name
    events.insert(3, {"t": 0.7, "ev": "tx", "link": "ea", "dst": "addr:9", "size": 30})  # nobody
    data = observations(events, REAL_LINKS)
    assert len(data.frames) == 21 + 2 and sum(not o.delivered for o in data.frames[:2]) == 2


def test_the_scene_comes_from_the_trace_as_it_was_at_each_moment():
    """A run line says ea and eb are simulated, a reload makes them real, another simulated again:
    only the frames between the two reloads are the real links'."""
    def view(backend):
        return {"links": {name: {"vehicle": info.vehicle, "backend": backend if name != "sim" else "sim",
                                 "address": info.address, "tx_channel": "ac", "rx_channel": "ac"}
                          for name, info in REAL_LINKS.items()}}
    events = [{"t": 0.0, "ev": "run", "run": "r", "scene": "x", "scene_view": view("sim")}]
    body = [e for e in real_trace() if e["ev"] != "run"]
    events += [e for e in body if e["t"] < 10]
    events.append({"t": 10.0, "ev": "reload", "scene": "x", "scene_view": view("evologics")})
    events += [e for e in body if 10 <= e["t"] < 30]
    events.append({"t": 30.0, "ev": "reload", "scene": "x", "scene_view": view("sim")})
    events += [e for e in body if e["t"] >= 30]
    data = observations(events, None)
    assert [round(o.t) for o in data.frames] == [11, 13, 15, 17, 19, 21, 23, 25, 27, 29]
    with pytest.raises(FitError, match="no frames sent by real links"):
        observations([e for e in events if e["ev"] != "reload"], None)
