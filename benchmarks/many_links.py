#!/usr/bin/env python3
"""Hundreds of real-time links in one daemon: delivery lateness at the applications and the daemon's CPU.

The daemon (a subprocess, ``hilgate run``) serves ``--links`` simulated links in pairs, each pair on a
channel of its own (15 m apart at 1500 m/s: 10 ms of propagation), every link ``gli: [socket]`` (so
500 links need no POSIX queue).  ``--readers`` application processes hold the links' Unix sockets:
each link sends ``--rate`` frames per second to its partner (phases spread evenly), and every frame
received is timestamped on receipt (``time.perf_counter``, CLOCK_MONOTONIC, the daemon's clock too).

Lateness = receipt − the wall time of the frame's model delivery time (the ``t`` of RECV).  Each reader
relates the daemon's model clock to its own with POSE requests: a reply's ``t`` was read between the
request's send ``w0`` and the reply's receipt ``w1``, so model time 0 is in ``[w0 − t, w1 − t]``.
Lateness is reported as an upper bound (origin = the largest ``w0 − t``) with the width of the
interval (the smallest round trip): the true lateness is at most that much smaller.

The daemon's CPU is its user + system time (``/proc/PID/stat``) over the measured window, per wall
second; the readers' is printed apart.  ``--spin fixed`` runs the daemon with the fixed 0.15 ms linger
after every input and fixed 0.3 ms spin before timers (as before the adaptive spin), alternating with
``adaptive`` over ``--repeats`` runs.

The processes are pinned (``placement.py``): **same CPU** (the daemon and every reader on one CPU) and
**across CPUs** (the readers on one, the daemon on the other), one after the other, each first in turn.
There is no anchor here: the bare timer loop beside a daemon is realtime_lateness.py's.

    python benchmarks/many_links.py [--links 500] [--rate 10] [--seconds 20] [--readers 10]
                                    [--spin adaptive|fixed|both] [--repeats 1] [--placement same|across|both]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import selectors
import socket
import struct
import sys
import time
import uuid

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from daemon_harness import Daemon, cpu_seconds  # noqa: E402
from placement import Placement, choose, pin  # noqa: E402

HEADER = struct.Struct(">IB")
RECV_HEAD = struct.Struct(">BBd")
SEND, RECV, COMMAND, REPLY = 3, 4, 7, 8

LAUNCH = """\
import sys
if sys.argv.pop(1) == "fixed":
    from hilgate.core import realtime, waiting

    class FixedWait(waiting.AdaptiveWait):  # the fixed spin and linger of earlier versions
        def overslept(self, late):
            pass

        def keep_polling(self, now):
            return now - self.last_input <= self.linger_s

    realtime.AdaptiveWait = FixedWait
from hilgate.cli import main
sys.exit(main())
"""


def scene_text(prefix: str, links: int) -> str:
    lines = ["name: many-links", "seed: 1", "channels:"]
    pairs = links // 2
    lines += [f"  c{i}: {{speed_mps: 1500}}" for i in range(pairs)]
    lines += ["vehicles:", "  va: {pose: {static: [0, 0, 0]}}", "  vb: {pose: {static: [15, 0, 0]}}", "links:"]
    for i in range(pairs):
        for side, vehicle, address in (("a", "va", 1), ("b", "vb", 2)):
            lines.append(f"  {prefix}{i}{side}: {{vehicle: {vehicle}, channel: c{i}, address: {address}, "
                         f"bitrate_bps: 100000, packet: vl2b, gli: [socket]}}")
    return "\n".join(lines) + "\n"


def message(kind: int, body: bytes) -> bytes:
    return HEADER.pack(len(body) + 1, kind) + body


def read_messages(buffer: bytearray) -> list[tuple[int, bytes]]:
    """Whole ``(type, body)`` messages out of ``buffer`` (this benchmark's own framing, by the length)."""
    out = []
    while len(buffer) >= 5:
        length, kind = HEADER.unpack_from(buffer)
        if len(buffer) < 4 + length:
            break
        out.append((kind, bytes(buffer[5:4 + length])))
        del buffer[:4 + length]
    return out


def clock_origin(sock: socket.socket, samples: int = 30) -> tuple[float, float]:
    """(latest possible model-time-0 on this process's perf_counter, the smallest round trip)."""
    buffer = bytearray()
    best_origin, best_rtt = -1e18, 1e18
    request = message(COMMAND, json.dumps({"class": "POSE"}).encode())
    sock.setblocking(True)
    for _ in range(samples):
        w0 = time.perf_counter()
        sock.sendall(request)
        reply = None
        while reply is None:
            buffer += sock.recv(65536)
            for kind, body in read_messages(buffer):
                if kind == REPLY:
                    reply = json.loads(body)
        w1 = time.perf_counter()
        best_origin = max(best_origin, w0 - reply["t"])
        best_rtt = min(best_rtt, w1 - w0)
        time.sleep(0.002)
    sock.setblocking(False)
    return best_origin, best_rtt


def reader(runtime: str, links: list[tuple[str, int]], rate: float, start: float, stop: float,
           warmup: float, phase0: float, result, cpu: int | None = None) -> None:
    """One application process: sends on its links at ``rate`` and timestamps every frame received."""
    pin(cpu)
    selector = selectors.DefaultSelector()
    socks = []
    for link_id, partner in links:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.connect(os.path.join(runtime, "gli", f"{link_id}.sock"))
        socks.append((sock, partner))
    origin, rtt = clock_origin(socks[0][0])
    buffers = {}
    for sock, _ in socks:
        sock.setblocking(False)
        buffers[sock.fileno()] = bytearray()
        selector.register(sock, selectors.EVENT_READ)
    period = 1.0 / rate
    n = len(socks)
    # link k of this reader sends at start + phase0 + k * period / n + j * period
    sends = [message(SEND, bytes([partner]) + b"m" * 16) for _, partner in socks]
    next_k, next_round = 0, 0
    lateness = []
    received = sent = 0
    cpu0 = time.process_time()
    while True:
        now = time.perf_counter()
        due = start + phase0 + next_round * period + next_k * period / n
        while due <= now and due < stop:
            try:
                socks[next_k][0].send(sends[next_k])
                sent += 1 if start + warmup <= time.perf_counter() <= stop else 0  # when it left, not when due
            except BlockingIOError:
                pass
            next_k += 1
            if next_k == n:
                next_k, next_round = 0, next_round + 1
            due = start + phase0 + next_round * period + next_k * period / n
        if now > stop + 0.5:
            break
        for key, _ in selector.select(max(0.0, min(due, stop + 0.5) - time.perf_counter())):
            sock = key.fileobj
            try:
                data = sock.recv(65536)
            except BlockingIOError:
                continue
            received_at = time.perf_counter()
            buffer = buffers[sock.fileno()]
            buffer += data
            for kind, body in read_messages(buffer):
                if kind != RECV:
                    continue
                _src, _dst, t = RECV_HEAD.unpack_from(body)
                if start + warmup <= origin + t <= stop:
                    lateness.append(received_at - (origin + t))
                    received += 1
    cpu = time.process_time() - cpu0
    for sock, _ in socks:
        sock.close()
    result.put((lateness, sent, received, rtt, cpu))


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * (len(ordered) - 1) + 0.5))]


def run_once(args: argparse.Namespace, spin: str, placement: Placement) -> dict:
    """The readers on the placement's step 0, the daemon on step 1."""
    prefix = "ml" + uuid.uuid4().hex[:6] + "_"
    daemon = Daemon(scene_text(prefix, args.links), args=("--max-clients", str(args.links + 16)),
                    cpu=placement.cpu(1), launch=("-c", LAUNCH, spin), ready_timeout=120)
    runtime = daemon.runtime
    try:
        pairs = args.links // 2
        all_links = [(f"{prefix}{i}a", 2) for i in range(pairs)] + [(f"{prefix}{i}b", 1) for i in range(pairs)]
        groups = [all_links[r::args.readers] for r in range(args.readers)]
        start = time.perf_counter() + 2.0 + 0.05 * args.readers  # readers connect and calibrate meanwhile
        stop = start + args.warmup + args.seconds
        result = mp.Queue()
        processes = [mp.Process(target=reader, args=(runtime, group, args.rate, start, stop, args.warmup,
                                                      r / args.readers / args.rate / len(group), result,
                                                      placement.cpu(0)))
                     for r, group in enumerate(groups)]
        for process in processes:
            process.start()
        time.sleep(max(0.0, start + args.warmup - time.perf_counter()))
        cpu0, wall0 = cpu_seconds(daemon.process.pid), time.perf_counter()
        time.sleep(max(0.0, stop - time.perf_counter()))
        cpu1, wall1 = cpu_seconds(daemon.process.pid), time.perf_counter()
        outcomes = [result.get(timeout=120 + args.seconds) for _ in processes]
        for process in processes:
            process.join()
    finally:
        daemon.close()
    lateness = [value for outcome in outcomes for value in outcome[0]]
    return {
        "spin": spin,
        "placement": placement.name,
        "sent": sum(o[1] for o in outcomes),
        "received": sum(o[2] for o in outcomes),
        "lateness": lateness,
        "clock_width": max(o[3] for o in outcomes),
        "daemon_cpu": (cpu1 - cpu0) / (wall1 - wall0),
        "reader_cpu": sum(o[4] for o in outcomes) / (args.seconds + args.warmup),
    }


def report(r: dict, args: argparse.Namespace) -> str:
    late = r["lateness"]
    if not late:
        return f"{r['placement']:>11}, {r['spin']:>8}: no frame received"
    return (f"{r['placement']:>11}, {r['spin']:>8}: {r['received']} frames delivered in the window, {r['sent']} sent in it; lateness at the "
            f"applications p50 {percentile(late, 0.5) * 1e3:.3f} ms, p99 {percentile(late, 0.99) * 1e3:.3f} ms, "
            f"max {max(late) * 1e3:.3f} ms (upper bounds, at most {r['clock_width'] * 1e3:.3f} ms high); "
            f"daemon CPU {r['daemon_cpu']:.2f} s/s; readers {r['reader_cpu']:.2f} s/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--links", type=int, default=500)
    parser.add_argument("--rate", type=float, default=10.0, help="frames per second each link sends")
    parser.add_argument("--seconds", type=float, default=20.0, help="measured window")
    parser.add_argument("--warmup", type=float, default=2.0, help="seconds before the window (not measured)")
    parser.add_argument("--readers", type=int, default=10, help="application processes holding the links")
    parser.add_argument("--spin", choices=("adaptive", "fixed", "both"), default="adaptive")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--placement", choices=("same", "across", "both"), default="both")
    args = parser.parse_args()
    chosen, why_not = choose(args.placement)
    if args.links < 2 or args.links % 2:
        parser.error("--links must be even (links come in pairs)")
    spins = ("adaptive", "fixed") if args.spin == "both" else (args.spin,)
    print(f"{args.links} links (gli: [socket]) at {args.rate:g} frames/s each, {args.readers} reader processes, "
          f"{args.seconds:g} s measured after {args.warmup:g} s; load average {os.getloadavg()[0]:.2f} at start")
    for placement in chosen:
        print(f"{placement.name:>11}: {placement.describe(['readers', 'daemon'])}")
    if why_not:
        print(why_not)
    for repeat in range(args.repeats):
        for k in range(len(chosen)):
            placement = chosen[(repeat + k) % len(chosen)]  # each placement goes first in turn
            for spin in spins:
                print(report(run_once(args, spin, placement), args), flush=True)
    print(f"load average {os.getloadavg()[0]:.2f} at the end (lateness p99 <= 1 ms is the target on a quiet host)")


if __name__ == "__main__":
    main()
