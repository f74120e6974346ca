"""The medium's incremental collision bookkeeping against a brute-force reference.

The medium prunes and splits its per-receiver lists for speed.  Here random scenes are simulated,
and every outcome in the trace is recomputed from the transmissions alone, the slow obvious way:
an arrival collides iff another arrival at the same receiver overlaps it by more than 1 ns, or (half
duplex) the receiver's own transmission does.
"""

import io
import json
import math
import random

import pytest

from hilgate.scene import load_scene_text
from hilgate.sim.simulate import simulate

EPS = 1e-9


def random_scene(seed: int, sparse: bool = False) -> tuple[str, dict]:
    """3-7 modems within 800 m; ``sparse``: 20-30 over 5 km, so the medium's grid by max range (900 m)
    leaves most static pairs out of its neighbour lists."""
    rng = random.Random(seed)
    n = rng.randint(20, 30) if sparse else rng.randint(3, 7)
    spread = 2500 if sparse else 800
    positions = {f"v{i}": [rng.uniform(-spread, spread), rng.uniform(-spread, spread), rng.uniform(0, 50)]
                 for i in range(n)}
    duplex = {f"l{i}": rng.choice(["half", "full"]) for i in range(n)}
    max_range = {f"l{i}": rng.choice([math.inf, 900.0]) for i in range(n)}
    duration = 30 if sparse else 120
    lines = ["seed: %d" % seed, f"duration_s: {duration}", "channels: {ac: {speed_mps: 1500}}", "vehicles:"]
    for name, p in positions.items():
        lines.append(f"  {name}: {{pose: {{static: {p}}}}}")
    lines.append("links:")
    for i in range(n):
        rng_text = "[0, .inf]" if max_range[f"l{i}"] == math.inf else "[0, 900]"
        lines.append(f"  l{i}: {{vehicle: v{i}, address: {i + 1}, bitrate_bps: 2000, duplex: {duplex[f'l{i}']}, "
                     f"range_m: {rng_text}, tx_delay_s: {rng.choice([0, 0.01])}}}")
    lines.append("flows:")
    for i in range(n):
        dst = rng.choice([f"l{j}" for j in range(n) if j != i] + ['"*"'])
        lines.append(f"  - {{from: l{i}, to: {dst}, size_bytes: {rng.randint(5, 120)}, "
                     f"rate_hz: {rng.uniform(0.2, 1.5):.3f}, poisson: true}}")
    info = {"positions": {f"l{i}": positions[f"v{i}"] for i in range(n)}, "duplex": duplex, "range": max_range,
            "duration": duration}
    return "\n".join(lines) + "\n", info


@pytest.mark.parametrize("seed, sparse", [(seed, False) for seed in range(12)] + [(seed, True) for seed in range(4)])
def test_outcomes_match_a_brute_force_recomputation(seed, sparse):
    text, info = random_scene(seed, sparse)
    trace = io.StringIO()
    simulate(load_scene_text(text), trace=trace)
    events = [json.loads(line) for line in trace.getvalue().splitlines()]
    links = list(info["positions"])
    address = {link: i + 1 for i, link in enumerate(links)}
    txs = [e for e in events if e["ev"] == "tx"]
    airtime = {e["pkt"]: e["size"] * 8 / 2000 for e in txs}

    # every arrival of every transmission at every receiver in range
    arrivals: dict[str, list[tuple[float, float, int]]] = {link: [] for link in links}
    own: dict[str, list[tuple[float, float]]] = {link: [] for link in links}
    for e in txs:
        sender = e["link"]
        own[sender].append((e["t"], e["t"] + airtime[e["pkt"]]))
        for receiver in links:
            if receiver == sender:
                continue
            d = math.dist(info["positions"][sender], info["positions"][receiver])
            if d > info["range"][sender]:
                continue
            start = e["t"] + d / 1500
            arrivals[receiver].append((start, start + airtime[e["pkt"]], e["pkt"]))

    expected = {}
    for receiver, spans in arrivals.items():
        for start, end, pkt in spans:
            collided = any(o_pkt != pkt and o_start < end - EPS and start < o_end - EPS
                           for o_start, o_end, o_pkt in spans)
            if info["duplex"][receiver] == "half":
                collided = collided or any(s < end - EPS and start < e - EPS for s, e in own[receiver])
            expected[(receiver, pkt)] = ("col" if collided else "ok", end)

    judged = [e for e in events if e["ev"] in ("rx", "err") and e.get("cause") != "range"]
    assert len(judged) > 50
    end_of_run = info["duration"]
    for e in judged:
        outcome, end = expected[(e["link"], e["pkt"])]
        assert ("ok" if e["ev"] == "rx" else e["cause"]) == outcome, e
    # and nothing that should have been judged was left out (unless it ends after the run)
    judged_keys = {(e["link"], e["pkt"]) for e in judged}
    dst_of = {e["pkt"]: e["dst"] for e in txs}
    for (receiver, pkt), (_, end) in expected.items():
        if end <= end_of_run and dst_of[pkt] in (receiver, "*"):
            assert (receiver, pkt) in judged_keys
    # a frame addressed beyond the sender's range gets its range error at the addressed link, once
    expected_range = sorted((e["dst"], e["pkt"]) for e in txs if e["dst"] != "*"
                            and math.dist(info["positions"][e["link"]], info["positions"][e["dst"]]) > info["range"][e["link"]])
    assert sorted((e["link"], e["pkt"]) for e in events if e["ev"] == "err" and e.get("cause") == "range") == expected_range
    if sparse:
        assert expected_range  # the grid left pairs out, and their frames still get their errors
    assert address  # addresses are positional in random_scene
