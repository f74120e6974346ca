#!/usr/bin/env python3
"""Real-time delivery lateness at the application, against a bare timer loop, alternating in one run.

hilgate: the daemon (``hilgate run``, a subprocess) runs N simulated nodes on a 200 m ring around the
origin, one acoustic channel at 9600 bit/s, 1 ms intrinsic transmit delay, ``mac: none``.  Application
processes (``--apps``, each owning every ``apps``-th link through its Unix socket GLI, the client library
``hilgate.client``) broadcast 20-byte frames (``simple:20``) from every link as a Poisson process of
``--rate`` frames per second (gaps of at least 50 ms, so a frame never waits in its modem's FIFO) and read
what the others deliver.  Each frame carries its sender and the time it was sent; on receipt the
application stamps the time, and the **lateness** is that stamp minus when the model says the frame is
delivered: send time + intrinsic delay + air time (20 bytes at 9600 bit/s) + distance / 1500 m/s.  It holds
everything between the two applications that the model does not account for: the input hop into the
daemon, its timers, the GLI write and the application's read.

Bare: one process runs a sleep-then-spin timer loop (what ``hilgate.core.realtime`` does, nothing else)
over Poisson due times at the rate hilgate delivers at (N × rate × (N − 1) per second) and writes each due
time to an application process over a Unix socket, which stamps it on receipt: the floor this host gives a
timer plus one hop at this moment.

ns-3 (``--ns3-python PATH``, a Python with the PyPI ``ns3`` wheel; ``make bench`` passes ``NS3_PYTHON``):
the same scene in ns-3's own real-time scheduler, ``RealtimeSimulatorImpl`` (``benchmarks/ns3_realtime.py``:
N UAN nodes on the same ring, the same bit rate, frame size and Poisson broadcasts, ALOHA).  At each
reception that ends well, plain C++ writes the wall-clock time the event was due to a socket whose other
end this process reads and stamps: a timer's lateness in ns-3 plus one hop, the bare loop's measurement with
ns-3's scheduler and model in front.  Without the option, or when that Python cannot import ``ns``, ns-3 is
"not run" with the reason.

Every process is pinned (``placement.py``), in two placements: **same CPU** (everything on one CPU) and
**across CPUs** (the applications, and the bare loop's and ns-3's reader, on one; the daemon, the bare
timer loop and ns-3 on the other).  The sides alternate (each goes first in turn from one repeat to the
next, and so does each placement), ``--repeats`` runs of each per placement.  Printed per run: p50, p99,
max and min lateness in ms, deliveries, the daemon's CPU per wall second; then, per placement, the p99s
min/median/max and the ratios hilgate/bare and hilgate/ns-3 of the p99 (DESIGN.md: p99 <= 0.25 ms and
max <= 1 ms on a quiet host, within 1.2 x the bare loop's p99 on a loaded one).

    python benchmarks/realtime_lateness.py [--seconds 20] [--nodes 50] [--rate 0.5] [--repeats 3] [--warm-up 2]
                                           [--read-after 1] [--placement same|across|both] [--ns3-python PATH]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import multiprocessing as mp
import os
import random
import selectors
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from daemon_harness import Daemon, cpu_seconds  # noqa: E402
from peers import check_python, spread  # noqa: E402
from placement import Placement, choose, pin, pinned, pinned_command  # noqa: E402

NS3_SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "ns3_realtime.py")

BITRATE, TX_DELAY, ON_AIR, SPEED, RADIUS = 9600, 0.001, 20, 1500.0, 200.0
WARM_UP_S = 2.0  # from the applications' start to their first frame: every application has opened its links
READ_AFTER_S = 1.0  # the applications read on this long after their last frame: the frames still on their way
MIN_GAP = 0.05  # s between one link's frames: longer than its 17.7 ms on air, so none waits in the FIFO
PAYLOAD = struct.Struct("<Hd")  # sender index, send time (time.perf_counter: CLOCK_MONOTONIC, one clock per host)
TARGET_P99_MS, TARGET_MAX_MS, TARGET_LOADED = 0.25, 1.0, 1.2


def positions(nodes: int) -> list[tuple[float, float]]:
    return [(RADIUS * math.cos(2 * math.pi * i / nodes), RADIUS * math.sin(2 * math.pi * i / nodes))
            for i in range(nodes)]


def scene_text(nodes: int, prefix: str) -> str:
    lines = ["name: realtime-lateness", "seed: 1", f"channels: {{ac: {{speed_mps: {SPEED}}}}}", "vehicles:"]
    for i, (x, y) in enumerate(positions(nodes)):
        lines.append(f"  v{i}: {{pose: {{static: [{x!r}, {y!r}, 0]}}}}")
    lines.append("links:")
    for i in range(nodes):
        lines.append(f"  {prefix}{i}: {{vehicle: v{i}, address: {i}, bitrate_bps: {BITRATE}, tx_delay_s: {TX_DELAY}, "
                     f"packet: 'simple:{ON_AIR}'}}")
    return "\n".join(lines) + "\n"


@contextlib.contextmanager
def instrument(priority: int) -> Iterator[None]:
    """The calling thread (an application or a reader: the measuring end) at SCHED_RR ``priority`` for the
    block (0: as it is), so that on a busy host the measurement waits for no neighbour: what the
    daemon's scheduling changes is then the daemon's share (``realtime_load.py``)."""
    if not priority:
        yield
        return
    before = os.sched_getscheduler(0), os.sched_getparam(0)
    os.sched_setscheduler(0, os.SCHED_RR | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    try:
        yield
    finally:
        os.sched_setscheduler(0, before[0] | os.SCHED_RESET_ON_FORK, before[1])  # (clearing the flag needs privilege)


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


# -- hilgate: applications on the socket GLI ----------------------------------------------------------


def _application(runtime_dir: str, links: list[tuple[int, str]], nodes: int, rate: float, seconds: float,
                 seed: int, start_at: float, result, cpu: int | None = None, priority: int = 0,
                 read_after: float = READ_AFTER_S) -> None:
    """Send from and read every link in ``links`` for ``seconds`` from ``start_at`` (perf_counter), then
    ``read_after`` seconds more for the frames on their way; put (lateness list, frames sent, deliveries)
    on ``result``.
    ``priority``: the instrument's (:func:`instrument`)."""
    pin(cpu)
    where = positions(nodes)
    delay = [[TX_DELAY + ON_AIR * 8 / BITRATE + math.dist(a, b) / SPEED for b in where] for a in where]
    with instrument(priority):
        send_and_read(runtime_dir, links, delay, rate, seconds, seed, start_at, result, read_after=read_after)


def send_and_read(runtime_dir: str, links: list[tuple[int, str]], delay: list[list[float]], rate: float,
                  seconds: float, seed: int, start_at: float, result, min_gap: float = MIN_GAP,
                  read_after: float = READ_AFTER_S) -> None:
    """The applications' loop: ``delay[sender][receiver]``, the model's delay from a frame's send to
    its delivery, between the scene's nodes by index; frames of ``ON_AIR`` bytes on air, sent by each
    link in ``links`` as a Poisson process of ``rate`` with gaps of at least ``min_gap``; read ``read_after``
    seconds after the sending ends."""
    from hilgate.client import Link

    opened = {index: Link.open(link_id, runtime_dir=runtime_dir) for index, link_id in links}
    selector = selectors.DefaultSelector()
    for index, link in opened.items():
        selector.register(link.sock, selectors.EVENT_READ, (index, link))
    rng = random.Random(f"{seed}/{links[0][1]}")
    due = {index: start_at + rng.expovariate(rate) for index in opened}
    stop, end = start_at + seconds, start_at + seconds + read_after
    late: list[float] = []
    sent = 0
    try:
        while True:
            now = time.perf_counter()
            if now >= end:
                break
            index = min(due, key=due.__getitem__)
            if due[index] <= now:
                if due[index] < stop:
                    opened[index].send(PAYLOAD.pack(index, time.perf_counter()).ljust(ON_AIR - 3, b"\0"))
                    sent += 1
                    due[index] += max(min_gap, rng.expovariate(rate))
                else:
                    due[index] = math.inf
                continue
            for key, _ in selector.select(min(due[index], end) - now):
                receiver, link = key.data
                link._pump(0.0)  # one read of what is there (READY/BUSY states too); recv() would wait for a frame
                received = time.perf_counter()  # on receipt: the frames are in this process
                while link.inbox:
                    message = link.inbox.popleft()
                    sender, sent_at = PAYLOAD.unpack_from(message.data)
                    late.append(received - sent_at - delay[sender][receiver])
    finally:
        selector.close()
        for link in opened.values():
            link.close()
    result.put((late, sent))


def add_application_timing(parser, warm_up: float = WARM_UP_S) -> None:
    """``--warm-up`` and ``--read-after``, the applications' waits around their sending (shared with
    realtime_load.py and hosts_scale.py)."""
    parser.add_argument("--warm-up", type=float, default=warm_up,
                        help="seconds from the applications' start to their first frame (every link opened)")
    parser.add_argument("--read-after", type=float, default=READ_AFTER_S,
                        help="seconds the applications read on after their last frame (the frames on their way)")


def through_hilgate(nodes: int, rate: float, seconds: float, apps: int, seed: int, daemon_args: tuple[str, ...],
                    placement: Placement, priority: int = 0, warm_up: float = WARM_UP_S,
                    read_after: float = READ_AFTER_S):
    """The applications on the placement's step 0 (at the instrument's ``priority``), the daemon on step 1;
    they send from ``warm_up`` seconds after they start (every link opened by then) and read ``read_after``
    seconds after their last frame.  Returns the lateness, the frame-receiver pairs sent, the daemon's CPU
    per wall second, and what the daemon counted (delivered, drops) and said it runs at (``scheduling``)."""
    prefix = f"rt{os.getpid()}x{seed}{placement.name[0]}_"
    names = [f"{prefix}{i}" for i in range(nodes)]
    daemon = Daemon(scene_text(nodes, prefix), tuple(names), daemon_args, cpu=placement.cpu(1))
    try:
        result = mp.Queue()
        start_at = time.perf_counter() + warm_up
        workers = [mp.Process(target=_application, args=(
            daemon.runtime, [(i, names[i]) for i in range(k, nodes, apps)], nodes, rate, seconds,
            seed, start_at, result, placement.cpu(0), priority, read_after)) for k in range(apps)]
        for worker in workers:
            worker.start()
        cpu0, wall0 = cpu_seconds(daemon.process.pid), time.perf_counter()
        outcomes = [result.get(timeout=seconds + 60) for _ in workers]
        cpu, wall = cpu_seconds(daemon.process.pid) - cpu0, time.perf_counter() - wall0
        for worker in workers:
            worker.join()
        status = daemon.status()
        links = status["links"]
    finally:
        daemon.close()
    late = [x for lateness, _ in outcomes for x in lateness]
    sent = sum(n for _, n in outcomes)
    counted = {"delivered": sum(link["rx_packets"] for link in links), "drops": sum(link["drops"] for link in links),
               "scheduling": status.get("scheduling", {}).get("text", "not said")}
    return late, sent * (nodes - 1), cpu / wall, counted


# -- bare: a timer loop and one hop -------------------------------------------------------------------


def _timer_loop(sock: socket.socket, rate: float, seconds: float, seed: int, realtime_priority: int,
                cpu: int | None = None) -> None:
    """Sleep until 0.3 ms before each due time, spin the rest (as hilgate's loop does), write the due time."""
    import select

    pin(cpu)
    from hilgate.core.realtime import lower_timer_slack

    lower_timer_slack()
    if realtime_priority:
        from hilgate.core.realtime import make_realtime

        make_realtime(realtime_priority)
    epoll = select.epoll()
    rng = random.Random(seed)
    t = time.perf_counter() + 0.5
    end = t + seconds
    pack = struct.Struct("<d").pack
    while t < end:
        t += rng.expovariate(rate)
        while True:
            wait = t - time.perf_counter()
            if wait > 0.0003:
                select.select([epoll.fileno()], [], [], wait - 0.0003)
            elif wait <= 0:
                break
        sock.send(pack(t))
    sock.send(b"")
    epoll.close()
    sock.close()


def _read_due_times(here: socket.socket, timeout: float) -> list[float]:
    """Read 8-byte due times (CLOCK_MONOTONIC) until end of file; the lateness of each on receipt."""
    here.settimeout(timeout)
    late = []
    unpack = struct.Struct("<d").unpack
    while True:
        message = here.recv(64)
        received = time.perf_counter()
        if not message:
            return late
        late.append(received - unpack(message)[0])


def bare(rate: float, seconds: float, seed: int, realtime_priority: int, placement: Placement,
         priority: int = 0) -> list[float]:
    """The reader (this thread, at the instrument's ``priority``) on the placement's step 0, the timer
    loop on step 1 (at ``realtime_priority``, as the daemon's ``--realtime-priority``)."""
    here, there = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    loop = mp.Process(target=_timer_loop, args=(there, rate, seconds, seed, realtime_priority, placement.cpu(1)))
    loop.start()
    there.close()
    with pinned(placement.cpu(0)), instrument(priority):
        late = _read_due_times(here, seconds + 60)
    loop.join()
    here.close()
    return late


def ns3_realtime(python: str, nodes: int, rate: float, seconds: float, seed: int, realtime_priority: int,
                 placement: Placement, priority: int = 0) -> tuple[list[float], dict]:
    """ns3_realtime.py under ``python`` on the placement's step 1, its reader (this thread, at the
    instrument's ``priority``) on step 0: the lateness of each delivery on receipt, and the script's JSON
    summary."""
    here, there = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    argv = [python, NS3_SCRIPT, "--fd", str(there.fileno()), "--nodes", str(nodes), "--sim-time", repr(seconds),
            "--rate", repr(rate), "--min-gap", repr(MIN_GAP), "--size", str(ON_AIR - 3), "--bitrate", str(BITRATE),
            "--radius", repr(RADIUS), "--seed", str(seed), "--realtime-priority", str(realtime_priority)]
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        process = subprocess.Popen(pinned_command(argv, placement.cpu(1)), stdout=out, stderr=err, text=True,
                                   pass_fds=(there.fileno(),))
        there.close()
        try:
            with pinned(placement.cpu(0)), instrument(priority):
                late = _read_due_times(here, seconds + 300)  # (importing ns-3 takes seconds)
        finally:
            here.close()
            process.wait()
        out.seek(0)
        err.seek(0)
        lines, errors = out.read().strip().splitlines(), err.read().strip().splitlines()
    if process.returncode != 0 or not lines:
        raise RuntimeError(f"ns3_realtime.py exited with {process.returncode}: {(errors or ['(no output)'])[-1]}")
    return late, json.loads(lines[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="of sending, per hilgate and ns-3 run")
    parser.add_argument("--bare-seconds", type=float, default=10.0, help="per bare run")
    parser.add_argument("--nodes", type=int, default=50)
    parser.add_argument("--rate", type=float, default=0.5, help="frames per second per node")
    parser.add_argument("--apps", type=int, default=2, help="application processes sharing the links")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each side per placement, alternating")
    add_application_timing(parser)
    parser.add_argument("--placement", choices=("same", "across", "both"), default="both")
    parser.add_argument("--realtime-priority", type=int, default=0,
                        help="real-time priority for the daemon, the bare loop and ns-3, as `hilgate run --realtime-priority` "
                             "(SCHED_RR for the loop's thread; realtime_load.py compares with and without, on a busy host)")
    parser.add_argument("--ns3-python", help="a Python with the ns3 wheel: run ns-3's real-time scheduler alongside")
    args = parser.parse_args()
    why_not = check_python(args.ns3_python, "ns")
    daemon_args = ("--realtime-priority", str(args.realtime_priority)) if args.realtime_priority else ()
    setup = f"SCHED_RR {args.realtime_priority}" if args.realtime_priority else "normal scheduling"
    deliveries_per_s = args.nodes * args.rate * (args.nodes - 1)
    chosen, across_not_run = choose(args.placement)
    print(f"{args.nodes} nodes, {args.rate:g} frames/s each, {args.apps} application processes on the socket GLI, "
          f"{setup}; bare loop at {deliveries_per_s:,.0f} timers/s; {args.repeats} run(s) of each per placement, "
          f"alternating", flush=True)
    for placement in chosen:
        ns3 = f"; ns-3: {placement.describe(['reader', 'ns-3'])}" if why_not is None else ""
        print(f"{placement.name:>11}: {placement.describe(['applications', 'daemon'])} (bare: "
              f"{placement.describe(['reader', 'timer loop'])}{ns3})", flush=True)
    if across_not_run:
        print(across_not_run, flush=True)
    print(f"ns-3: {'RealtimeSimulatorImpl run alongside (' + args.ns3_python + ')' if why_not is None else 'not run (' + why_not + ')'}",
          flush=True)
    sides = ["bare", "hilgate"] + (["ns-3"] if why_not is None else [])
    p99s: dict[tuple[str, str], list[float]] = {}
    for repeat in range(1, args.repeats + 1):
        for k in range(len(chosen)):
            placement = chosen[(repeat - 1 + k) % len(chosen)]  # each placement goes first in turn
            j = (repeat - 1) % len(sides)
            for side in sides[j:] + sides[:j]:  # and each side, from one repeat to the next
                if side not in sides:
                    continue  # (ns-3 failed in an earlier run)
                if side == "ns-3":
                    try:
                        late, raw = ns3_realtime(args.ns3_python, args.nodes, args.rate, args.seconds, repeat,
                                                 args.realtime_priority, placement)
                    except (RuntimeError, OSError, ValueError) as exc:
                        print(f"ns-3: failed, not run again ({exc})", flush=True)
                        sides.remove("ns-3")
                        continue
                    extra = (f"{len(late):,} deliveries read, {raw['sent']:,} frames sent in {args.seconds:g} s; "
                             f"its scheduler's own lateness at those events (before the hop) mean "
                             f"{raw['event_lateness_mean_ms']:.3f} ms, max {raw['event_lateness_max_ms']:.3f} ms")
                elif side == "bare":
                    late = bare(deliveries_per_s, args.bare_seconds, repeat, args.realtime_priority, placement)
                    extra = f"{len(late):,} timers in {args.bare_seconds:g} s"
                else:
                    late, expected, cpu, counted = through_hilgate(args.nodes, args.rate, args.seconds, args.apps, repeat,
                                                                   daemon_args, placement, warm_up=args.warm_up,
                                                                   read_after=args.read_after)
                    extra = (f"{len(late):,} deliveries read of {expected:,} frame-receiver pairs sent in {args.seconds:g} s "
                             f"(the daemon delivered {counted['delivered']:,}, dropped {counted['drops']}; the rest were "
                             f"lost on the channel); daemon CPU {cpu:.2f} s per wall s")
                if not late:
                    raise RuntimeError(f"{side}: no lateness measured in run {repeat}")
                ms = [1e3 * x for x in late]
                p99s.setdefault((placement.name, side), []).append(percentile(ms, 0.99))
                print(f"run {repeat}, {placement.name:>11}, {side:>7}: lateness at the application p50 "
                      f"{percentile(ms, 0.5):.3f} ms  p99 {percentile(ms, 0.99):.3f} ms  max {max(ms):.3f} ms  "
                      f"min {min(ms):.3f} ms; {extra}", flush=True)
    print("p99 lateness at the application, min / median / max over the runs:")
    for placement in chosen:
        got = {side: p99s.get((placement.name, side), []) for side in ("bare", "hilgate", "ns-3")}
        line = f"  {placement.name:>11}: bare {spread(got['bare'], 3)} ms, hilgate {spread(got['hilgate'], 3)} ms"
        line += f", ns-3 {spread(got['ns-3'], 3)} ms" if got["ns-3"] else ", ns-3 not run"
        line += f"; ratio hilgate / bare {spread([h / b for h, b in zip(got['hilgate'], got['bare'])])}"
        if got["ns-3"]:
            line += f", hilgate / ns-3 {spread([h / n for h, n in zip(got['hilgate'], got['ns-3'])])}"
        print(line, flush=True)
    medians = [statistics.median(p99s[(p.name, 'hilgate')]) for p in chosen]
    print(f"(targets: p99 <= {TARGET_P99_MS} ms and max <= {TARGET_MAX_MS} ms on a quiet host; within "
          f"{TARGET_LOADED} x the bare loop's p99 on a loaded one; hilgate's median p99 now "
          + ", ".join(f"{m:.3f} ms {p.name}" for m, p in zip(medians, chosen)) + ")")


if __name__ == "__main__":
    main()
