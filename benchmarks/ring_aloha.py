#!/usr/bin/env python3
"""Virtual-time speed against ns-3 UAN: the ALOHA ring of ../shared/peers/README.md.

A sink at the origin and N-1 senders on a ring of 500 m; every sender offers 35-byte frames (32 B of
payload + ns-3's 3-byte UAN header, as on air) to the sink as a Poisson process of 0.05 frame/s, at
1 kbit/s, ideal propagation at 1500 m/s, half duplex, ``mac: none``; 36 000 simulated seconds.  The
scene goes through the normal scene loader and ``hilgate.sim.simulate``, exactly what ``hilgate sim``
runs.  Printed per N: the sink's delivery ratio beside ns-3's, the arrivals handled per wall second
(every frame reaching every receiver in range, as the bare heapq baseline counts them) and the wall
time beside ns-3's.

    python benchmarks/ring_aloha.py                      # N = 10, 50, 100
    python benchmarks/ring_aloha.py --nodes 50 --profile # where the time goes
"""

from __future__ import annotations

import argparse
import cProfile
import json
import math
import pstats
import time

from hilgate.scene import load_scene_text
from hilgate.sim.simulate import Simulation

# ns-3 3.44 UAN on the same kind of 2-core machine (../shared/peers/README.md)
NS3 = {10: (0.789, 0.27, 478_000), 50: (0.257, 6.3, 343_000), 100: (0.064, 24.1, 182_000)}


def ring_scene(nodes: int, sim_time: float, seed: int, radius: float = 500.0) -> str:
    lines = [
        "name: ring-aloha", f"seed: {seed}", f"duration_s: {sim_time}",
        "channels: {ac: {speed_mps: 1500}}", "vehicles:", "  sink: {pose: {static: [0, 0, 0]}}",
    ]
    for i in range(1, nodes):
        angle = 2 * math.pi * (i - 1) / (nodes - 1)
        lines.append(f"  s{i}: {{pose: {{static: [{radius * math.cos(angle)!r}, {radius * math.sin(angle)!r}, 0]}}}}")
    lines.append("links:")
    lines.append("  sink: {vehicle: sink, address: 0, bitrate_bps: 1000}")
    for i in range(1, nodes):
        lines.append(f"  s{i}: {{vehicle: s{i}, address: {i}, bitrate_bps: 1000}}")
    lines.append("flows:")
    for i in range(1, nodes):
        lines.append(f"  - {{from: s{i}, to: sink, size_bytes: 35, rate_hz: 0.05, poisson: true}}")
    return "\n".join(lines) + "\n"


def bench(nodes: int, sim_time: float, seed: int, profile: bool = False) -> dict:
    scene = load_scene_text(ring_scene(nodes, sim_time, seed), f"ring-{nodes}")
    simulation = Simulation(scene)
    profiler = cProfile.Profile() if profile else None
    if profiler:
        profiler.enable()
    started = time.perf_counter()
    summary = simulation.run()
    wall = time.perf_counter() - started
    if profiler:
        profiler.disable()
        pstats.Stats(profiler).sort_stats("tottime").print_stats(12)
    offered = sum(f["offered"] for f in summary["flows"])
    received = sum(f["rx_packets"] for f in summary["flows"])
    count = simulation.world.medium.arrivals
    return {
        "nodes": nodes, "sim_s": sim_time, "offered": offered, "sink_rx": received,
        "pdr_sink": round(received / offered, 4), "arrivals": count, "events": simulation.clock.events,
        "wall_s": round(wall, 3), "arrivals_per_wall_s": round(count / wall),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nodes", type=int, nargs="*", default=[10, 50, 100])
    parser.add_argument("--sim-time", type=float, default=36000.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--profile", action="store_true", help="print the top functions by own time")
    parser.add_argument("--json", action="store_true", help="one JSON line per N instead of the table")
    args = parser.parse_args()
    if not args.json:
        print(f"{'N':>4} {'PDR':>7} {'ns-3 PDR':>9} {'diff':>6} {'arrivals':>11} {'wall s':>8} {'ns-3 wall s':>11} "
              f"{'arrivals/s':>11} {'ns-3 arr/s*':>11}")
    for n in args.nodes:
        result = bench(n, args.sim_time, args.seed, args.profile)
        ref = NS3.get(n) if args.sim_time == 36000.0 else None
        if args.json:
            if ref:
                result.update(ns3_pdr=ref[0], ns3_wall_s=ref[1], ns3_arrivals_per_wall_s=ref[2])
            print(json.dumps(result))
            continue
        ref_pdr, ref_wall, ref_rate = ref if ref else (math.nan, math.nan, math.nan)
        print(f"{n:>4} {result['pdr_sink']:>7.3f} {ref_pdr:>9.3f} {100 * (result['pdr_sink'] - ref_pdr):>+5.1f}p "
              f"{result['arrivals']:>11,} {result['wall_s']:>8.2f} {ref_wall:>11.2f} "
              f"{result['arrivals_per_wall_s']:>11,} {ref_rate:>11,.0f}")
    if not args.json:
        print("* ns-3 counts PHY RxOk + RxError, i.e. only the arrivals its PHY locked on to; hilgate counts every "
              "frame reaching every receiver in range, so compare wall seconds for the same work.")


if __name__ == "__main__":
    main()
