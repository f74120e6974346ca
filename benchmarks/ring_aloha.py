#!/usr/bin/env python3
"""Virtual-time speed against ns-3 UAN, both run here: the ALOHA ring of ../shared/peers/README.md.

A sink at the origin and N-1 senders on a ring of 500 m; every sender offers 35-byte frames (32 B of
payload + ns-3's 3-byte UAN header, as on air) to the sink as a Poisson process of 0.05 frame/s, at
1 kbit/s, ideal propagation at 1500 m/s, half duplex.  hilgate runs the scene through the normal scene
loader and ``hilgate.sim.simulate`` (what ``hilgate sim`` runs), each run in its own process.

With ``--ns3-python PATH`` (a Python that has the PyPI ``ns3`` wheel) the peer script
``ns3_uan_aloha.py`` runs the same scenario in the same invocation, alternating with hilgate, ``--repeats``
times per N; printed per N: both delivery ratios, both wall times (the event loop only: not the import,
not the set-up) and min/median/max of ns-3 wall / hilgate wall, and of the peak memory of each process.
Without it ns-3 is "not run".

Work is counted the same way on both sides: **arrivals in range**, every transmission reaching every
other node (ideal propagation, no range limit, so transmissions × (N − 1); hilgate's medium counts them,
ns-3's PHY transmissions are multiplied out).  ns-3's own PHY count (RxOk + RxError, only the arrivals
its PHY locked on to) and hilgate's judged arrivals are not the same thing and are not compared.

By default hilgate's senders queue a frame offered while they transmit (``mac: none``: the modem's FIFO);
ns-3's UanMacAloha drops it.  ``--drop-when-busy`` gives hilgate's senders ``mac: aloha``, which drops it
too, so both run exactly the same protocol.

    python benchmarks/ring_aloha.py                                  # hilgate only (ns-3 not run)
    python benchmarks/ring_aloha.py --ns3-python ~/ns3venv/bin/python --drop-when-busy
    python benchmarks/ring_aloha.py --nodes 50 --profile             # where hilgate's time goes
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
# ``peers`` (subprocess, tempfile) is imported by the parent only: a ``--one`` run's peak memory is hilgate's

from hilgate.scene import load_scene_text  # noqa: E402
from hilgate.sim.simulate import Simulation  # noqa: E402

PAYLOAD, HEADER, RATE, BITRATE, RADIUS = 32, 3, 0.05, 1000, 500.0


def ring_scene(nodes: int, sim_time: float, seed: int, mac: str = "none", radius: float = RADIUS) -> str:
    lines = [
        "name: ring-aloha", f"seed: {seed}", f"duration_s: {sim_time}",
        "channels: {ac: {speed_mps: 1500}}", "vehicles:", "  sink: {pose: {static: [0, 0, 0]}}",
    ]
    for i in range(1, nodes):
        angle = 2 * math.pi * (i - 1) / (nodes - 1)
        lines.append(f"  s{i}: {{pose: {{static: [{radius * math.cos(angle)!r}, {radius * math.sin(angle)!r}, 0]}}}}")
    lines.append("links:")
    lines.append(f"  sink: {{vehicle: sink, address: 0, bitrate_bps: {BITRATE}, mac: {mac}}}")
    for i in range(1, nodes):  # beyond 254, wide addresses (simulated links), skipping 255 (broadcast)
        lines.append(f"  s{i}: {{vehicle: s{i}, address: {i if i < 255 else i + 1}, bitrate_bps: {BITRATE}, mac: {mac}}}")
    lines.append("flows:")
    for i in range(1, nodes):
        lines.append(f"  - {{from: s{i}, to: sink, size_bytes: {PAYLOAD + HEADER}, rate_hz: {RATE}, poisson: true}}")
    return "\n".join(lines) + "\n"


def bench(nodes: int, sim_time: float, seed: int, mac: str, profile: bool = False) -> dict:
    """One hilgate run in this process."""
    import resource

    scene = load_scene_text(ring_scene(nodes, sim_time, seed, mac), f"ring-{nodes}")
    simulation = Simulation(scene)
    profiler = None
    if profile:  # (imported only here: the profiler's modules would count in every run's peak memory)
        import cProfile
        import pstats

        profiler = cProfile.Profile()
        profiler.enable()
    started = time.perf_counter()
    summary = simulation.run()
    wall = time.perf_counter() - started
    if profiler:
        profiler.disable()
        pstats.Stats(profiler, stream=sys.stderr).sort_stats("tottime").print_stats(12)
    offered = sum(f["offered"] for f in summary["flows"])
    received = sum(f["rx_packets"] for f in summary["flows"])
    transmissions = sum(link["tx_packets"] for link in summary["links"])
    return {
        "nodes": nodes, "sim_s": sim_time, "mac": mac, "offered": offered, "tx": transmissions,
        "dropped_busy": simulation.recorder.mac_events.get("drop", 0), "sink_rx": received,
        "pdr_sink": received / offered if offered else math.nan,
        "arrivals_in_range": simulation.world.medium.arrivals, "events": simulation.clock.events,
        "wall_s": wall, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def hilgate_run(nodes: int, sim_time: float, seed: int, mac: str) -> dict:
    from peers import run_json

    result, peak = run_json([sys.executable, os.path.abspath(__file__), "--one", str(nodes), "--sim-time",
                             repr(sim_time), "--seed", str(seed), "--mac", mac])
    result["peak_rss_mb"] = peak
    return result


def ns3_run(python: str, script: str, nodes: int, sim_time: float, seed: int) -> dict:
    from peers import run_json

    raw, peak = run_json([python, script, "--nodes", str(nodes), "--sim-time", repr(sim_time), "--seed", str(seed),
                          "--rate", repr(RATE), "--size", str(PAYLOAD), "--bitrate", str(BITRATE),
                          "--radius", repr(RADIUS), "--mac", "aloha", "--prop", "ideal", "--traffic", "poisson"])
    if not raw.get("traces_hooked", True):
        raise RuntimeError("ns3_uan_aloha.py could not hook its PHY traces")
    return {"nodes": nodes, "offered": raw["app_tx"], "tx": raw["phy_tx"], "dropped_busy": raw["mac_drop"],
            "sink_rx": raw["sink_rx"], "pdr_sink": raw["pdr_sink"] if raw["pdr_sink"] is not None else math.nan,
            "arrivals_in_range": raw["phy_tx"] * (nodes - 1), "phy_locked": raw["phy_rx_ok"] + raw["phy_rx_err"],
            "events": raw["events"], "wall_s": raw["wall_s"], "peak_rss_mb": peak}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nodes", type=int, nargs="*", default=[10, 50])
    parser.add_argument("--sim-time", type=float, default=36000.0, help="simulated s (at 3 600 s N = 10 runs in tens of ms: noise)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=3, help="alternating hilgate / ns-3 runs per N (>= 1)")
    parser.add_argument("--drop-when-busy", action="store_true",
                        help="hilgate's senders use mac: aloha (drop a frame offered while transmitting), as ns-3")
    parser.add_argument("--ns3-python", help="a Python with the ns3 wheel: run ns-3 UAN alongside")
    parser.add_argument("--ns3-script", help="the peer script (default: ../shared/peers/ns3_uan_aloha.py)")
    parser.add_argument("--profile", action="store_true", help="one hilgate run per N in this process, profiled")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # one hilgate run, one JSON line
    parser.add_argument("--mac", default="none", help=argparse.SUPPRESS)
    args = parser.parse_args()
    mac = "aloha" if args.drop_when_busy else args.mac
    if args.one:
        print(json.dumps(bench(args.one, args.sim_time, args.seed, mac)))
        return
    if args.profile:
        for n in args.nodes:
            print(json.dumps(bench(n, args.sim_time, args.seed, mac, profile=True)))
        return
    from peers import PEERS, check_python, spread

    args.ns3_script = args.ns3_script or os.path.join(PEERS, "ns3_uan_aloha.py")
    why_not = check_python(args.ns3_python, "ns") or (None if os.path.exists(args.ns3_script)
                                                      else f"no peer script {args.ns3_script}")
    queueing = ("mac: aloha, a frame offered while transmitting is dropped (as ns-3's UanMacAloha)" if mac == "aloha"
                else "mac: none, a frame offered while transmitting waits in the FIFO (ns-3 drops it: --drop-when-busy)")
    print(f"ALOHA ring, {args.sim_time:g} simulated s, seed {args.seed}, {args.repeats} repeat(s); hilgate {queueing}.")
    print("Work counted on both sides as arrivals in range = transmissions x (N - 1); wall = the event loop only.")
    print(f"ns-3: {'run alongside, alternating (' + args.ns3_python + ')' if why_not is None else 'not run (' + why_not + ')'}")
    print(f"{'N':>4} {'rep':>3} {'side':>7} {'offered':>8} {'dropped':>7} {'PDR':>6} {'arrivals':>11} {'wall s':>8} "
          f"{'arrivals/s':>11} {'peak MB':>8}", flush=True)
    for n in args.nodes:
        runs: dict[str, list[dict]] = {"hilgate": [], "ns-3": []}
        for repeat in range(1, args.repeats + 1):
            sides = [("hilgate", lambda: hilgate_run(n, args.sim_time, args.seed, mac))]
            if why_not is None:
                sides.append(("ns-3", lambda: ns3_run(args.ns3_python, args.ns3_script, n, args.sim_time, args.seed)))
            if repeat % 2 == 0:
                sides.reverse()  # alternate which goes first, so a drift in the host's load hits both
            for side, run in sides:
                r = run()
                runs[side].append(r)
                print(f"{n:>4} {repeat:>3} {side:>7} {r['offered']:>8,} {r['dropped_busy']:>7,} {r['pdr_sink']:>6.3f} "
                      f"{r['arrivals_in_range']:>11,} {r['wall_s']:>8.3f} {r['arrivals_in_range'] / r['wall_s']:>11,.0f} "
                      f"{r['peak_rss_mb']:>8.1f}", flush=True)
        hil = runs["hilgate"]
        line = (f"N = {n}: hilgate PDR {statistics.median(r['pdr_sink'] for r in hil):.3f}, wall s min/median/max "
                f"{spread([r['wall_s'] for r in hil], 3)}")
        if runs["ns-3"]:
            ns3 = runs["ns-3"]
            pdr_diff = 100 * (statistics.median(r['pdr_sink'] for r in hil) - statistics.median(r['pdr_sink'] for r in ns3))
            wall_ratio = [b["wall_s"] / a["wall_s"] for a, b in zip(hil, ns3)]
            work_ratio = [(a["arrivals_in_range"] / a["wall_s"]) / (b["arrivals_in_range"] / b["wall_s"])
                          for a, b in zip(hil, ns3)]
            mem_ratio = [b["peak_rss_mb"] / a["peak_rss_mb"] for a, b in zip(hil, ns3)]
            line += (f"; ns-3 PDR {statistics.median(r['pdr_sink'] for r in ns3):.3f} ({pdr_diff:+.1f} points)\n"
                     f"  ratio ns-3 wall / hilgate wall, min/median/max: {spread(wall_ratio)}\n"
                     f"  ratio hilgate / ns-3 arrivals in range per wall s: {spread(work_ratio)}\n"
                     f"  ratio ns-3 / hilgate peak memory: {spread(mem_ratio)}")
        else:
            line += "; ns-3 not run"
        print(line, flush=True)


if __name__ == "__main__":
    main()
