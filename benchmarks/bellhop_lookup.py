#!/usr/bin/env python3
"""What a channel that knows the water costs: the preparation (BELLHOP run as a separate program, its
files read, reduced and cached) and the cost per arrival of the lookup, against the Thorp model in the
same run.

- Preparation: the issue's shallow case (100 m of water, a summer profile, sand, 12 kHz): a 51 × 501
  TL grid and 26 × 101 arrivals, for one source depth and for the default eleven, from an empty cache
  (BELLHOP is pelagic in ``.venv-bellhop``: ``make .venv-bellhop/.installed``), with a fan of 1 001 beams
  as the figures before issue 38 had: the fan found by convergence (``beams: auto``, the default) takes
  16 to 32 times the beams here, and what that costs is measured by ``docs/water_examples.py``.
- Per arrival, alone: the step the medium takes for a moving pair, d = |a − b|, the delay, the PER,
  with the physical model (Thorp, 15·log r) and with the BELLHOP lookup (``BellhopPath.at`` then
  ``Reception.per``), alternated, 5 repeats of 200 000 arrivals.
- Per arrival in a simulation: ``hilgate sim`` of one sender broadcasting to 20 moving receivers, the
  same scene with and without ``water:``, alternated, 3 repeats: wall time over arrivals.

    python benchmarks/bellhop_lookup.py [--quick]

``--quick`` runs every step on a small grid and few arrivals (seconds, not minutes): the tests run it so
that the benchmark keeps working as the code it measures changes; its figures mean nothing.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import statistics
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests"))

from hilgate.channel.prepare import ready_channels  # noqa: E402
from hilgate.channel.runner import BellhopError, find_program, prepare_fields  # noqa: E402
from hilgate.models.bellhop_fields import BellhopChannel  # noqa: E402
from hilgate.models.environment import SEDIMENTS, Water  # noqa: E402
from hilgate.scene import load_scene_text  # noqa: E402

SUMMER = ((0.0, 1521.0), (15.0, 1520.0), (25.0, 1510.0), (40.0, 1500.0), (100.0, 1498.0))
SHALLOW = Water(depth_m=100.0, sound_speed=SUMMER, bottom=SEDIMENTS["sand"], range_m=5000.0, ranges=501, depths=51,
                source_depths=1, arrival_ranges=101, arrival_depths=26, beams=1001)

SCENE = """\
name: bench
seed: 1
duration_s: 100
channels:
  ac:
    speed_mps: 1500
{water}
vehicles:
  s: {{pose: {{static: [0, 0, 10]}}}}
{vehicles}
links:
  ls: {{vehicle: s, address: 1, model: evologics-s2cr-18-34, error: {{kind: physical}}}}
{links}
flows:
  - {{from: ls, to: "*", size_bytes: 32, interval_s: 0.05}}
"""
WATER = """    water:
      depth_m: 100
      sound_speed: [[0, 1521], [15, 1520], [25, 1510], [40, 1500], [100, 1498]]
      bottom: sand
      beams: 1001
      grid: {{range_m: 5000, ranges: {ranges}, depths: {depths}, source_depths: {sources}}}"""
FULL = {"ranges": 501, "depths": 51, "sources": 11, "arrival_ranges": 101, "arrival_depths": 26, "arrivals": 200_000,
        "repeats": 5, "sim_repeats": 3, "sim_s": 100.0}
QUICK = {"ranges": 51, "depths": 11, "sources": 2, "arrival_ranges": 11, "arrival_depths": 6, "arrivals": 2_000,
         "repeats": 1, "sim_repeats": 1, "sim_s": 5.0}
SIZE = dict(FULL)


def scene_text(water: bool, receivers: int = 20) -> str:
    rng = random.Random(5)
    vehicles, links = [], []
    for i in range(receivers):
        x0, x1 = rng.uniform(200, 3000), rng.uniform(200, 3000)
        z0, z1 = rng.uniform(5, 95), rng.uniform(5, 95)
        vehicles.append(f"  v{i}: {{pose: {{path: {{start: [{x0:.1f}, 0, {z0:.1f}], "
                        f"legs: [{{to: [{x1:.1f}, 50, {z1:.1f}], duration_s: 100}}]}}}}}}")
        links.append(f"  l{i}: {{vehicle: v{i}, address: {i + 2}, model: evologics-s2cr-18-34, error: {{kind: physical}}}}")
    water_text = WATER.format(**SIZE) if water else ""
    return SCENE.format(water=water_text, vehicles="\n".join(vehicles), links="\n".join(links))


def ratio_line(name: str, ours: list[float], anchor: list[float]) -> str:
    ratios = sorted(o / a for o, a in zip(ours, anchor))
    return f"{name}: ratio min/median/max {ratios[0]:.2f} / {statistics.median(ratios):.2f} / {ratios[-1]:.2f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="a small grid and few arrivals (a check, not figures)")
    if parser.parse_args().quick:
        SIZE.update(QUICK)
    try:
        program = find_program()
    except BellhopError as exc:
        print(f"BELLHOP: not run ({exc})")
        return 0
    print(f"BELLHOP program: {program.name.replace(ROOT + os.sep, '')}")

    # -- preparation ---------------------------------------------------------------------------------
    grid = {"ranges": SIZE["ranges"], "depths": SIZE["depths"], "arrival_ranges": SIZE["arrival_ranges"],
            "arrival_depths": SIZE["arrival_depths"]}
    shape = f"TL {SIZE['depths']} x {SIZE['ranges']} + arrivals {SIZE['arrival_depths']} x {SIZE['arrival_ranges']}"
    for sources in (1, SIZE["sources"]):
        water = Water(**{**SHALLOW.__dict__, **grid, "source_depths": sources})
        times = []
        for _ in range(3 if sources == 1 else 1):
            with tempfile.TemporaryDirectory() as cache:
                t0 = time.perf_counter()
                fields = prepare_fields(water, [12000.0], program=program, cache=cache)[0]
                times.append(time.perf_counter() - t0)
        print(f"preparation, {sources} source depth(s), {shape} at 12 kHz, empty cache: "
              + " / ".join(f"{t:.2f}" for t in times) + " s")
        with tempfile.TemporaryDirectory() as cache:
            prepare_fields(water, [12000.0], program=program, cache=cache)
            t0 = time.perf_counter()
            prepare_fields(water, [12000.0], program=program, cache=cache)
            print(f"  the same from the cache: {1000 * (time.perf_counter() - t0):.1f} ms")

    # -- per arrival, alone --------------------------------------------------------------------------
    shared = tempfile.TemporaryDirectory()  # the scenes' fields, computed once for what follows
    cache = os.path.join(shared.name, "bellhop")
    scene = load_scene_text(scene_text(True, 1), "bench.yaml")
    channels = ready_channels(scene.channels, scene.links, program=program, cache=cache)
    paths: BellhopChannel = channels["ac"].propagation
    sender, receiver = scene.links["ls"].params, scene.links["l0"].params
    thorp = receiver.error.path_from(sender.acoustic, sender.bitrate_bps)
    bellhop = paths.bind(sender, receiver).model
    rng = random.Random(1)
    geometry = [((0.0, 0.0, rng.uniform(5, 95)), (rng.uniform(100, 4900), rng.uniform(-50, 50), rng.uniform(5, 95)))
                for _ in range(SIZE["arrivals"])]
    n = len(geometry)

    def thorp_pass() -> float:
        t0 = time.perf_counter()
        per, dist = thorp.per, math.dist
        for a, b in geometry:
            d = dist(a, b)
            start = 0.0 + d / 1500.0
            per(d, 32)
        return (time.perf_counter() - t0) / n

    def bellhop_pass() -> float:
        t0 = time.perf_counter()
        at, dist = bellhop.at, math.dist
        for a, b in geometry:
            d = dist(a, b)
            reception = at(a, b)
            start = 0.0 + reception.delay
            reception.per(d, 32)
        return (time.perf_counter() - t0) / n

    thorp_ns, bellhop_ns = [], []
    for _ in range(SIZE["repeats"]):
        thorp_ns.append(thorp_pass() * 1e9)
        bellhop_ns.append(bellhop_pass() * 1e9)
    print(f"per arrival, alone ({n} arrivals x {SIZE['repeats']}, alternated): Thorp {statistics.median(thorp_ns):.0f} ns "
          f"(min {min(thorp_ns):.0f}), BELLHOP lookup {statistics.median(bellhop_ns):.0f} ns (min {min(bellhop_ns):.0f})")
    print("  " + ratio_line("BELLHOP / Thorp", bellhop_ns, thorp_ns))

    # -- per arrival, in a simulation ----------------------------------------------------------------
    from hilgate.sim.simulate import Simulation

    with shared:
        os.environ["HILGATE_CACHE"] = shared.name
        plain = load_scene_text(scene_text(False), "bench.yaml")
        watery = load_scene_text(scene_text(True), "bench.yaml")
        Simulation(watery, 1.0, None, None).run(False)  # fields into the cache, outside the timing
        per_plain, per_water = [], []
        for _ in range(SIZE["sim_repeats"]):
            for scene_, out in ((plain, per_plain), (watery, per_water)):
                sim = Simulation(scene_, SIZE["sim_s"], None, None)
                t0 = time.perf_counter()
                sim.run(False)
                wall = time.perf_counter() - t0
                arrivals = sim.world.medium.arrivals
                out.append(wall / arrivals * 1e6)
        print(f"hilgate sim, 1 sender to 20 moving receivers, {SIZE['sim_s']:g} s ({arrivals} arrivals), wall time per "
              f"arrival: Thorp {statistics.median(per_plain):.2f} us, BELLHOP {statistics.median(per_water):.2f} us "
              f"(medians of {SIZE['sim_repeats']})")
        print("  " + ratio_line("BELLHOP / Thorp", per_water, per_plain))
    return 0


if __name__ == "__main__":
    sys.exit(main())
