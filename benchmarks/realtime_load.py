#!/usr/bin/env python3
"""Delivery lateness at 50 nodes on a busy host, with and without ``hilgate run --realtime``, beside the
bare timer loop and ns-3's real-time scheduler in the same conditions and at the same priority.

The scene, the applications and the two anchors are ``realtime_lateness.py``'s (imported): N simulated
nodes on a 200 m ring, Poisson broadcasts of 20-byte frames, lateness = when the application has the
frame minus when the model delivers it; the bare loop (a sleep-then-spin timer loop and one hop) and
ns-3's ``RealtimeSimulatorImpl`` (``ns3_realtime.py``, with ``--ns3-python``) measured at the same point.
Four conditions:

- **load**: *quiet* (nothing added; the machine's other work goes on and the load average is printed),
  or *busy*: ``tests/loadkit.py``'s ``Neighbours`` (imported: 4 CPU hogs, 4 processes that compute 5 ms
  and rest 1 ms, one writing 256 MiB files and syncing them), unpinned, at normal priority, started
  before each busy run and stopped after it;
- **scheduling**: *normal*, or *realtime*: the daemon with ``--realtime`` (what it got is printed, as
  it says it in ``hilgate status``), and the anchors' one time-keeping thread given the same (SCHED_RR
  10 and memory locked: the bare timer loop through ``hilgate.core.priority``, ns-3's simulation thread
  once its scene is built, ``ns3_realtime.py --realtime-priority``).  The same for all three is fair:
  each is the one thread whose wake-ups are the deliveries.

The measuring end (the applications, the anchors' readers) runs at SCHED_RR 11, one above what is
measured, in every condition where the host allows it (``--instrument normal``: at normal priority):
on a busy host an application at normal priority waits behind the neighbours for its own wake-up, which
would hide what the daemon's scheduling changes.  A dccomms application of the lab at normal priority
sees that wait on top.

Every process of a measurement is pinned (``placement.py``): **same CPU** or **across CPUs**; the
neighbours are not (they are the rest of the machine).  Loads, schedulings and sides alternate (each goes
first in turn from one repeat to the next), ``--repeats`` runs of each.  Printed per run: p50, p99 and max
lateness in ms, the daemon's CPU per wall second and the neighbours' (what real-time priority took from
them); then a table per placement of the medians of p50 and p99 over the runs (p99 min-max in brackets).

    python benchmarks/realtime_load.py [--seconds 10] [--bare-seconds 5] [--nodes 50] [--rate 0.5] [--repeats 2]
                                       [--placement same|across|both] [--instrument realtime|normal] [--ns3-python PATH]
                                       [--settle 2] [--warm-up 2] [--read-after 1]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(1, os.path.join(os.path.dirname(HERE), "tests"))
from daemon_harness import cpu_seconds  # noqa: E402
from loadkit import Neighbours  # noqa: E402
from peers import check_python  # noqa: E402
from placement import Placement, choose  # noqa: E402
from realtime_lateness import add_application_timing, bare, ns3_realtime, percentile, through_hilgate  # noqa: E402

REALTIME = 10  # hilgate.core.priority.DEFAULT_PRIORITY: what `hilgate run --realtime` asks
INSTRUMENT = REALTIME + 1
LOADS = ("quiet", "busy")
SCHEDULINGS = ("normal", "realtime")
SETTLE_S = 2.0  # the neighbours started (Python's start-up) and their writer's first file under way


def why_no_real_time(priority: int) -> str | None:
    """Why this user may not take SCHED_RR ``priority`` (None: it may), asked of the kernel."""
    probe = subprocess.run([sys.executable, "-c", f"import os; os.sched_setscheduler(0, os.SCHED_RR, os.sched_param({priority}))"],
                           capture_output=True, text=True)
    return None if probe.returncode == 0 else (probe.stderr.strip().splitlines() or ["refused"])[-1]


def neighbours_cpu(neighbours: Neighbours | None) -> float:
    """CPU seconds the neighbours have used so far (0 with none)."""
    total = 0.0
    for process in neighbours.procs if neighbours is not None else ():
        try:
            total += cpu_seconds(process.pid)
        except OSError:
            pass  # (one that ended)
    return total


def run_side(side: str, args, placement: Placement, repeat: int, scheduling: str, instrument: int) -> tuple[list[float], str]:
    """One run of one side: the lateness (s) and a few words on what was run."""
    priority = REALTIME if scheduling == "realtime" else 0
    deliveries_per_s = args.nodes * args.rate * (args.nodes - 1)
    if side == "bare":
        late = bare(deliveries_per_s, args.bare_seconds, repeat, priority, placement, instrument)
        return late, f"{len(late):,} timers in {args.bare_seconds:g} s"
    if side == "ns-3":
        late, raw = ns3_realtime(args.ns3_python, args.nodes, args.rate, args.seconds, repeat, priority, placement,
                                 instrument)
        return late, f"{len(late):,} deliveries read, {raw['sent']:,} frames sent in {args.seconds:g} s"
    daemon_args = ("--realtime",) if priority else ()
    late, expected, cpu, counted = through_hilgate(args.nodes, args.rate, args.seconds, args.apps, repeat, daemon_args,
                                                   placement, instrument, warm_up=args.warm_up,
                                                   read_after=args.read_after)
    return late, (f"{len(late):,} deliveries read of {expected:,} pairs sent (the daemon dropped {counted['drops']}); "
                  f"daemon CPU {cpu:.2f} s per wall s; the daemon says: {counted['scheduling']}")


def measured(side: str, args, placement: Placement, repeat: int, load: str, scheduling: str,
             instrument: int) -> tuple[float, float, float | None] | None:
    """One run of one side in one condition, printed; its (p50, p99) in ms and the neighbours' CPU per wall
    second (None: quiet), or None if ns-3 failed.  Busy:
    the neighbours start before it (fresh for each run, so each finds the same load) and stop after it."""
    neighbours = None
    if load == "busy":
        limit = max(args.seconds, args.bare_seconds) + 300  # a hang guard (ns-3 starts in seconds, slower when busy)
        neighbours = Neighbours(args.hogs, args.wakers, args.writers, args.writer_mib, limit_s=limit)
        time.sleep(args.settle)
    try:
        loadavg = os.getloadavg()[0]
        cpu0, wall0 = neighbours_cpu(neighbours), time.perf_counter()
        try:
            late, extra = run_side(side, args, placement, repeat, scheduling, instrument)
        except (RuntimeError, OSError, ValueError) as exc:
            if side != "ns-3":
                raise
            print(f"ns-3: {exc}", flush=True)
            return None
        share = (neighbours_cpu(neighbours) - cpu0) / (time.perf_counter() - wall0)
    finally:
        if neighbours is not None:
            neighbours.stop()
    if not late:
        raise RuntimeError(f"{side}: no lateness measured in run {repeat}")
    ms = [1e3 * x for x in late]
    p50, p99 = percentile(ms, 0.5), percentile(ms, 0.99)
    print(f"run {repeat}, {placement.name:>11}, {load:>5}, {scheduling:>8}, {side:>7}: lateness "
          f"p50 {p50:.3f} ms  p99 {p99:.3f} ms  max {max(ms):.3f} ms; {extra}; load average "
          f"{loadavg:.2f}" + (f"; neighbours {share:.2f} CPU s per wall s" if neighbours else ""), flush=True)
    return p50, p99, share if neighbours else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="of sending, per hilgate and ns-3 run")
    parser.add_argument("--bare-seconds", type=float, default=5.0, help="per bare run")
    parser.add_argument("--nodes", type=int, default=50)
    parser.add_argument("--rate", type=float, default=0.5, help="frames per second per node")
    parser.add_argument("--apps", type=int, default=2, help="application processes sharing the links")
    parser.add_argument("--repeats", type=int, default=2, help="runs of each side per condition and placement")
    parser.add_argument("--placement", choices=("same", "across", "both"), default="both")
    parser.add_argument("--instrument", choices=("realtime", "normal"), default="realtime",
                        help=f"the applications and readers at SCHED_RR {INSTRUMENT} (default, where allowed) or normal")
    parser.add_argument("--hogs", type=int, default=4, help="busy: CPU-bound neighbours")
    parser.add_argument("--wakers", type=int, default=4, help="busy: neighbours computing 5 ms and resting 1 ms")
    parser.add_argument("--writers", type=int, default=1, help="busy: neighbours writing files and syncing them")
    parser.add_argument("--writer-mib", type=int, default=256, help="busy: MiB each writer writes before it syncs")
    parser.add_argument("--settle", type=float, default=SETTLE_S,
                        help="busy: seconds from the neighbours' start to the run (their writer's first file under way)")
    add_application_timing(parser)
    parser.add_argument("--ns3-python", help="a Python with the ns3 wheel: run ns-3's real-time scheduler alongside")
    args = parser.parse_args()
    why_not_ns3 = check_python(args.ns3_python, "ns")
    refused = why_no_real_time(INSTRUMENT)
    instrument = INSTRUMENT if args.instrument == "realtime" and refused is None else 0
    chosen, across_not_run = choose(args.placement)
    print(f"{args.nodes} nodes, {args.rate:g} frames/s each, {args.apps} application processes on the socket GLI; "
          f"bare loop at {args.nodes * args.rate * (args.nodes - 1):,.0f} timers/s; {args.repeats} run(s) of each side "
          f"per condition and placement, alternating", flush=True)
    print(f"busy: {args.hogs} CPU hogs, {args.wakers} wakers (5 ms on, 1 ms off), {args.writers} writer(s) syncing "
          f"{args.writer_mib} MiB files (tests/loadkit.py), unpinned, normal priority; quiet: none added", flush=True)
    print(f"realtime: the daemon with --realtime, the bare timer loop and ns-3's simulation thread at SCHED_RR {REALTIME} "
          f"with memory locked" + (f" (this user may not: {refused}; each falls back and says what it got)" if refused else ""),
          flush=True)
    print("instrument (applications, readers): " + (f"SCHED_RR {INSTRUMENT} in every condition" if instrument else
          "normal priority" + (f" (SCHED_RR refused: {refused})" if refused and args.instrument == "realtime" else "")),
          flush=True)
    for placement in chosen:
        print(f"{placement.name:>11}: {placement.describe(['applications', 'daemon'])} (bare: "
              f"{placement.describe(['reader', 'timer loop'])}; ns-3: {placement.describe(['reader', 'ns-3'])})", flush=True)
    if across_not_run:
        print(across_not_run, flush=True)
    print(f"ns-3: {'RealtimeSimulatorImpl run alongside (' + args.ns3_python + ')' if why_not_ns3 is None else 'not run (' + why_not_ns3 + ')'}",
          flush=True)
    sides = ["bare", "hilgate"] + (["ns-3"] if why_not_ns3 is None else [])
    got: dict[tuple[str, str, str, str], list[tuple]] = {}  # (placement, load, scheduling, side) → (p50, p99, neighbours)
    for repeat in range(1, args.repeats + 1):
        for k in range(len(chosen)):
            placement = chosen[(repeat - 1 + k) % len(chosen)]
            for m in range(len(LOADS)):
                load = LOADS[(repeat - 1 + m) % len(LOADS)]
                for n in range(len(SCHEDULINGS)):
                    scheduling = SCHEDULINGS[(repeat - 1 + n) % len(SCHEDULINGS)]
                    j = (repeat - 1) % len(sides)
                    for side in sides[j:] + sides[:j]:
                        if side not in sides:
                            continue  # (ns-3 failed in an earlier run)
                        outcome = measured(side, args, placement, repeat, load, scheduling, instrument)
                        if outcome is None:
                            print("ns-3: failed, not run again", flush=True)
                            sides.remove("ns-3")
                            continue
                        got.setdefault((placement.name, load, scheduling, side), []).append(outcome)
    print(f"lateness at the application, ms: median p50 / median p99 over the runs (p99 min-max):")
    for placement in chosen:
        print(f"  {placement.name}:")
        print(f"    {'load':>5}  {'scheduling':>10}  " + "  ".join(f"{side:>26}" for side in ("bare", "hilgate", "ns-3")))
        for load in LOADS:
            for scheduling in SCHEDULINGS:
                cells = []
                for side in ("bare", "hilgate", "ns-3"):
                    pairs = got.get((placement.name, load, scheduling, side))
                    if not pairs:
                        cells.append(f"{'not run':>26}")
                        continue
                    p99s = [p99 for _, p99, _ in pairs]
                    cells.append(f"{statistics.median(p for p, _, _ in pairs):7.3f} / {statistics.median(p99s):7.3f} "
                                 f"({min(p99s):.2f}-{max(p99s):.2f})".rjust(26))
                print(f"    {load:>5}  {scheduling:>10}  " + "  ".join(cells), flush=True)
    print("the busy neighbours' CPU s per wall s, median over the runs (what each side's scheduling left them):")
    for placement in chosen:
        for scheduling in SCHEDULINGS:
            shares = {side: [n for _, _, n in got.get((placement.name, "busy", scheduling, side), [])] for side in sides}
            print(f"  {placement.name:>11}, {scheduling:>8}: " + ", ".join(
                f"{side} {statistics.median(shares[side]):.2f}" for side in sides if shares[side]), flush=True)
    for placement in chosen:
        for load in LOADS:
            normal = got.get((placement.name, load, "normal", "hilgate"))
            fast = got.get((placement.name, load, "realtime", "hilgate"))
            if normal and fast:
                before = statistics.median(p99 for _, p99, _ in normal)
                after = statistics.median(p99 for _, p99, _ in fast)
                print(f"  {placement.name}, {load}: hilgate's median p99 {before:.3f} ms at normal priority, "
                      f"{after:.3f} ms with --realtime ({before / after:.1f} times less)", flush=True)


if __name__ == "__main__":
    main()
