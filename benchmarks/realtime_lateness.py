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

The two alternate (bare, hilgate, hilgate, bare, …), ``--repeats`` times each.  Printed per run: p50, p99
and max lateness in ms, deliveries, the daemon's CPU per wall second; then min/median/max of hilgate's
p99 over the bare loop's p99 (DESIGN.md: p99 <= 0.25 ms and max <= 1 ms on a quiet host, within 1.2 x the
bare loop's p99 on a loaded one).

With ``--ns3-python PATH`` (a Python with the PyPI ``ns3`` wheel) ns-3's real-time scheduler runs too,
alternating with the other two: the peer script ``ns3_uan_aloha.py --realtime`` (N nodes, the same rate
and bit rate, its senders to a sink), which reports how late its send events ran against the wall
clock, mean and max.  That is a timer's lateness inside ns-3, not a delivery's at an application, so it
is printed beside the others (min/median/max over the repeats) and not divided into them.  Without the
option ns-3 is "not run".

    python benchmarks/realtime_lateness.py [--seconds 20] [--nodes 50] [--rate 0.5] [--repeats 3] [--ns3-python PATH]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import os
import random
import selectors
import socket
import statistics
import struct
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gli_roundtrip import Daemon  # noqa: E402
from peers import PEERS, check_python, run_json, spread  # noqa: E402

BITRATE, TX_DELAY, ON_AIR, SPEED, RADIUS = 9600, 0.001, 20, 1500.0, 200.0
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


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


# -- hilgate: applications on the socket GLI ----------------------------------------------------------


def _application(runtime_dir: str, links: list[tuple[int, str]], nodes: int, rate: float, seconds: float,
                 seed: int, start_at: float, result) -> None:
    """Send from and read every link in ``links`` for ``seconds`` from ``start_at`` (perf_counter), then
    one more second for the frames on their way; put (lateness list, frames sent, deliveries) on ``result``."""
    from hilgate.client import Link

    where = positions(nodes)
    delay = [[TX_DELAY + ON_AIR * 8 / BITRATE + math.dist(a, b) / SPEED for b in where] for a in where]
    opened = {index: Link.open(link_id, runtime_dir=runtime_dir) for index, link_id in links}
    selector = selectors.DefaultSelector()
    for index, link in opened.items():
        selector.register(link.sock, selectors.EVENT_READ, (index, link))
    rng = random.Random(f"{seed}/{links[0][1]}")
    due = {index: start_at + rng.expovariate(rate) for index in opened}
    stop, end = start_at + seconds, start_at + seconds + 1.0
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
                    due[index] += max(MIN_GAP, rng.expovariate(rate))
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


def through_hilgate(nodes: int, rate: float, seconds: float, apps: int, seed: int, daemon_args: tuple[str, ...]):
    prefix = f"rt{os.getpid()}x{seed}_"
    names = [f"{prefix}{i}" for i in range(nodes)]
    daemon = Daemon(scene_text(nodes, prefix), tuple(names), daemon_args)
    try:
        result = mp.Queue()
        start_at = time.perf_counter() + 2.0  # every application has opened its links by then
        workers = [mp.Process(target=_application, args=(
            os.path.join(daemon.dir, "rt"), [(i, names[i]) for i in range(k, nodes, apps)], nodes, rate, seconds,
            seed, start_at, result)) for k in range(apps)]
        for worker in workers:
            worker.start()
        cpu0, wall0 = _cpu(daemon.process.pid), time.perf_counter()
        outcomes = [result.get(timeout=seconds + 60) for _ in workers]
        cpu, wall = _cpu(daemon.process.pid) - cpu0, time.perf_counter() - wall0
        for worker in workers:
            worker.join()
        links = daemon.status()["links"]
    finally:
        daemon.close()
    late = [x for lateness, _ in outcomes for x in lateness]
    sent = sum(n for _, n in outcomes)
    counted = {"delivered": sum(link["rx_packets"] for link in links), "drops": sum(link["drops"] for link in links)}
    return late, sent * (nodes - 1), cpu / wall, counted


def _cpu(pid: int) -> float:
    """CPU seconds (user + system) process ``pid`` has used so far (/proc, so it runs on)."""
    with open(f"/proc/{pid}/stat") as handle:
        fields = handle.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# -- bare: a timer loop and one hop -------------------------------------------------------------------


def _timer_loop(sock: socket.socket, rate: float, seconds: float, seed: int, realtime_priority: int) -> None:
    """Sleep until 0.3 ms before each due time, spin the rest (as hilgate's loop does), write the due time."""
    import select

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


def bare(rate: float, seconds: float, seed: int, realtime_priority: int) -> list[float]:
    here, there = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    loop = mp.Process(target=_timer_loop, args=(there, rate, seconds, seed, realtime_priority))
    loop.start()
    there.close()
    late = []
    unpack = struct.Struct("<d").unpack
    while True:
        message = here.recv(64)
        received = time.perf_counter()
        if not message:
            break
        late.append(received - unpack(message)[0])
    loop.join()
    here.close()
    return late


def ns3_realtime(python: str, script: str, nodes: int, rate: float, seconds: float, seed: int) -> dict:
    raw, _ = run_json([python, script, "--realtime", "--nodes", str(nodes), "--sim-time", repr(seconds), "--rate",
                       repr(rate), "--size", str(ON_AIR - 3), "--bitrate", str(BITRATE), "--radius", repr(RADIUS),
                       "--seed", str(seed)])
    return raw


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="of sending, per hilgate run")
    parser.add_argument("--bare-seconds", type=float, default=10.0, help="per bare run")
    parser.add_argument("--nodes", type=int, default=50)
    parser.add_argument("--rate", type=float, default=0.5, help="frames per second per node")
    parser.add_argument("--apps", type=int, default=2, help="application processes sharing the links")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each, alternating")
    parser.add_argument("--realtime-priority", type=int, default=0,
                        help="SCHED_FIFO priority for the daemon and the bare loop, as `hilgate run --realtime-priority`")
    parser.add_argument("--ns3-python", help="a Python with the ns3 wheel: run ns-3's real-time scheduler alongside")
    parser.add_argument("--ns3-script", default=os.path.join(PEERS, "ns3_uan_aloha.py"))
    args = parser.parse_args()
    why_not = check_python(args.ns3_python, "ns") or (None if os.path.exists(args.ns3_script)
                                                      else f"no peer script {args.ns3_script}")
    daemon_args = ("--realtime-priority", str(args.realtime_priority)) if args.realtime_priority else ()
    setup = f"SCHED_FIFO {args.realtime_priority}" if args.realtime_priority else "normal scheduling"
    deliveries_per_s = args.nodes * args.rate * (args.nodes - 1)
    print(f"{args.nodes} nodes, {args.rate:g} frames/s each, {args.apps} application processes on the socket GLI, "
          f"{setup}; bare loop at {deliveries_per_s:,.0f} timers/s; {args.repeats} runs of each, alternating", flush=True)
    print(f"ns-3: {'real-time scheduler run alongside (' + args.ns3_python + ')' if why_not is None else 'not run (' + why_not + ')'}",
          flush=True)
    p99s: dict[str, list[float]] = {"bare": [], "hilgate": []}
    ns3_mean, ns3_max = [], []
    sides = ["bare", "hilgate"] + (["ns-3"] if why_not is None else [])
    for repeat in range(1, args.repeats + 1):
        k = (repeat - 1) % len(sides)  # each side goes first in turn
        order = sides[k:] + sides[:k]
        for side in order:
            if side == "ns-3":
                raw = ns3_realtime(args.ns3_python, args.ns3_script, args.nodes, args.rate, args.seconds, repeat)
                ns3_mean.append(raw["send_lateness_mean_ms"])
                ns3_max.append(raw["send_lateness_max_ms"])
                print(f"run {repeat}    ns-3: send lateness of its real-time scheduler (a timer, not a delivery at an "
                      f"application) mean {raw['send_lateness_mean_ms']:.3f} ms  max {raw['send_lateness_max_ms']:.3f} ms; "
                      f"{raw['sends_late_over_1ms']:,} of {raw['app_tx']:,} sends later than 1 ms", flush=True)
                continue
            if side == "bare":
                late = bare(deliveries_per_s, args.bare_seconds, repeat, args.realtime_priority)
                extra = f"{len(late):,} timers in {args.bare_seconds:g} s"
            else:
                late, expected, cpu, counted = through_hilgate(args.nodes, args.rate, args.seconds, args.apps, repeat,
                                                               daemon_args)
                extra = (f"{len(late):,} deliveries read of {expected:,} frame-receiver pairs sent in {args.seconds:g} s "
                         f"(the daemon delivered {counted['delivered']:,}, dropped {counted['drops']}; the rest were lost "
                         f"on the channel); daemon CPU {cpu:.2f} s per wall s")
            ms = [1e3 * x for x in late]
            p99s[side].append(percentile(ms, 0.99))
            print(f"run {repeat} {side:>7}: lateness at the application p50 {percentile(ms, 0.5):.3f} ms  p99 "
                  f"{percentile(ms, 0.99):.3f} ms  max {max(ms):.3f} ms  min {min(ms):.3f} ms; {extra}", flush=True)
    ratios = [h / b for h, b in zip(p99s["hilgate"], p99s["bare"])]
    print(f"p99 lateness, min/median/max of {args.repeats}: bare {spread(p99s['bare'], 3)} ms, hilgate "
          f"{spread(p99s['hilgate'], 3)} ms; ratio hilgate / bare {spread(ratios)}")
    if ns3_mean:
        print(f"ns-3 real-time send lateness, min/median/max of {args.repeats}: mean {spread(ns3_mean, 3)} ms, "
              f"max {spread(ns3_max, 3)} ms (not divided into the above: not the same measurement point)")
    else:
        print("ns-3 real-time scheduler: not run")
    print(f"(targets: p99 <= {TARGET_P99_MS} ms and max <= {TARGET_MAX_MS} ms on a quiet host; within "
          f"{TARGET_LOADED} x the bare loop's p99 on a loaded one; median p99 now "
          f"{statistics.median(p99s['hilgate']):.3f} ms)")


if __name__ == "__main__":
    main()
