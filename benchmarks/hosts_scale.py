#!/usr/bin/env python3
"""Scale across hosts: 4 daemons × 50 links against one daemon carrying all 200, one channel.

The scene: ``4 × --links`` simulated links on one acoustic channel (1500 m/s, 64 kbit/s, 1 ms transmit
delay, 20-byte frames: 2.5 ms on air, ``mac: none``), in pairs 50 m apart, the pairs 1 km from each
other and every link's range 100 m: each frame reaches its pair's other end alone.  With hosts, link
``i`` of host ``h`` pairs with link ``i`` of host ``h XOR (1 + i mod 3)``: every pair crosses hosts and
every host talks to the three others.  One application process per host (``realtime_lateness.py``'s
loop, imported) sends from each of its links as a Poisson process of ``--rate`` frames per second (gaps
of at least 10 ms) through the socket GLI and reads what its links receive; the lateness is when it has
a frame minus when the model delivers it (send + 1 ms + 2.5 ms + 50 m / 1500 m/s), and so holds the
sending daemon's input hop, the receiving daemon's timer and the GLI hop out, and the network between
the daemons only when it is slower than the model's 33 ms of propagation.

- **4 daemons**: one per host, each in a network namespace of its own joined to the others by veth
  pairs and one bridge (``netns.py``: as root; elsewhere 4 daemons on loopback, and it says so), joined
  as shipped (mutual TLS with credentials from ``hilgate network init``, Zenoh's access control), host
  ``i`` connecting to hosts ``0 … i-1``: a full mesh.
- **1 daemon**: the same links and applications, the scene without hosts, one daemon serving them all.

Every daemon publishes each transmission of its links and runs the medium for its own receivers with
everyone's transmissions (``hilgate/daemon/network.py``): what spreading the links over hosts divides is
the GLI, the timers and the deliveries; what it does not is the medium's work on transmissions.  Nothing
is pinned: eight busy processes or more on this machine's CPUs leave no placement to choose, and the
kernel's is what a deployment gets.  The two sides alternate (each goes first in turn), ``--repeats``
runs of each.  Printed per run: lateness p50/p99/max over all deliveries and per host, each daemon's CPU
(seconds per wall second, over the sending window), frames delivered of those sent, what the daemons
dropped, and the transmissions heard too late or missing between hosts; then the medians over the runs.

    python benchmarks/hosts_scale.py [--links 50] [--rate 10] [--seconds 20] [--repeats 2] [--warm-up 3]
                                     [--read-after 1] [--loopback] [--realtime]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import os
import shutil
import statistics
import sys
import tempfile
import time
import uuid

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import netns  # noqa: E402
from daemon_harness import Daemon, cpu_seconds  # noqa: E402
from multihost import free_port  # noqa: E402
from realtime_lateness import ON_AIR, add_application_timing, percentile, send_and_read  # noqa: E402

HOSTS = ("A", "B", "C", "D")
BITRATE, TX_DELAY, SPEED = 64000, 0.001, 1500.0
PAIR_M, SPACING_M, RANGE_M = 50.0, 1000.0, 100.0
MIN_GAP = 0.01  # s between one link's frames: longer than its 3.5 ms from send to the end of its air time
ZENOH_PORT = 7447  # (in a namespace of its own each daemon has the whole port space)
WARM_UP_S = 3.0  # from the applications' start to their first frame: every link opened
FORK = mp.get_context("fork")  # (the benchmark's process has no thread and no Zenoh session: safe, and quick)


def partner(h: int, i: int) -> int:
    """The host of link ``i`` of host ``h``'s other end."""
    return h ^ (1 + i % 3)


def layout(per_host: int) -> list[tuple[int, int, tuple[float, float]]]:
    """(host, index on its host, position) of every link, by global index ``h * per_host + i``."""
    where = []
    for h in range(len(HOSTS)):
        for i in range(per_host):
            low, high = sorted((h, partner(h, i)))
            pair = 2 * i + (0 if low == 0 else 1)  # (index i has two pairs: the one with host 0, the other)
            where.append((h, i, (SPACING_M * pair, 0.0 if h == low else PAIR_M)))
    return where


def scene_text(per_host: int, prefix: str, hosts: bool, zenoh_prefix: str = "", credentials: str = "") -> str:
    lines = ["name: hosts-scale", "seed: 1", f"channels: {{ac: {{speed_mps: {SPEED}}}}}"]
    if hosts:
        lines.append(f"zenoh: {{prefix: {zenoh_prefix}, credentials: {credentials}}}")
    lines.append("vehicles:")
    where = layout(per_host)
    for k, (h, _, (x, y)) in enumerate(where):
        lines.append(f"  v{k}: {{pose: {{static: [{x!r}, {y!r}, 0]}}}}")
    lines.append("links:")
    for k, (h, _, _) in enumerate(where):
        host = f"host: {HOSTS[h]}, " if hosts else ""
        lines.append(f"  {prefix}{k}: {{vehicle: v{k}, {host}address: {k % 250 + 1}, bitrate_bps: {BITRATE}, "
                     f"tx_delay_s: {TX_DELAY}, range_m: [0, {RANGE_M}], packet: 'simple:{ON_AIR}', gli: [socket]}}")
    return "\n".join(lines) + "\n"


def delays(per_host: int) -> list[list[float]]:
    where = [p for _, _, p in layout(per_host)]
    return [[TX_DELAY + ON_AIR * 8 / BITRATE + math.dist(a, b) / SPEED for b in where] for a in where]


def _application(runtime_dir: str, links: list[tuple[int, str]], per_host: int, rate: float, seconds: float,
                 seed: int, start_at: float, result, read_after: float) -> None:
    send_and_read(runtime_dir, links, delays(per_host), rate, seconds, seed, start_at, result, MIN_GAP, read_after)


class Hosts:
    """The 4 daemons, each serving its host's links, in namespaces (``spaces``) or on loopback."""

    def __init__(self, per_host: int, prefix: str, spaces: netns.Namespaces | None, extra: tuple[str, ...] = ()):
        from hilgate.commands.credentials import init_network

        self.dir = tempfile.mkdtemp(prefix="hilgate-hosts-bench-")
        self.daemons: list[Daemon] = []
        try:
            credentials = os.path.join(self.dir, "creds")
            init_network(credentials, list(HOSTS), 1)
            text = scene_text(per_host, prefix, True, f"bench-{uuid.uuid4().hex[:8]}", credentials)
            if spaces is not None:
                endpoints = [f"tls/{spaces.address(h)}:{ZENOH_PORT}" for h in range(len(HOSTS))]
            else:
                endpoints = [f"tls/127.0.0.1:{free_port()}" for _ in HOSTS]
            for h, host in enumerate(HOSTS):
                args = ["--host", host, "--zenoh-listen", endpoints[h]]
                for other in endpoints[:h]:
                    args += ["--zenoh-connect", other]
                links = tuple(f"{prefix}{h * per_host + i}" for i in range(per_host))
                self.daemons.append(Daemon(text, links, (*args, *extra), directory=self.dir, name=host,
                                           within=spaces.command(h) if spaces is not None else ()))
            deadline = time.monotonic() + 60
            while not all(self._sees_all(d) for d in self.daemons):
                if time.monotonic() > deadline:
                    raise RuntimeError("the daemons did not all meet within 60 s")
                time.sleep(0.1)
        except BaseException:
            self.close()
            raise

    @staticmethod
    def _sees_all(daemon: Daemon) -> bool:
        views = daemon.status()["network"]["hosts"]
        return sum(1 for v in views if v["state"] == "up") >= len(HOSTS) - 1

    def runtime(self, h: int) -> str:
        return self.daemons[h].runtime

    def close(self) -> None:
        for daemon in self.daemons:
            daemon.close()
        shutil.rmtree(self.dir, ignore_errors=True)


class One:
    """One daemon serving every link."""

    def __init__(self, per_host: int, prefix: str, extra: tuple[str, ...] = ()):
        links = tuple(f"{prefix}{k}" for k in range(len(HOSTS) * per_host))
        self.daemons = [Daemon(scene_text(per_host, prefix, False), links, extra)]

    def runtime(self, h: int) -> str:
        return self.daemons[0].runtime

    def close(self) -> None:
        self.daemons[0].close()


def run(side: str, args, repeat: int, spaces: netns.Namespaces | None) -> dict:
    per_host = args.links
    prefix = f"hs{os.getpid()}x{repeat}{side[0]}_"
    extra = ("--realtime",) if args.realtime else ()
    setup = Hosts(per_host, prefix, spaces, extra) if side == "4 daemons" else One(per_host, prefix, extra)
    try:
        results = [FORK.Queue() for _ in HOSTS]
        start_at = time.perf_counter() + args.warm_up
        apps = [FORK.Process(target=_application, args=(
            setup.runtime(h), [(h * per_host + i, f"{prefix}{h * per_host + i}") for i in range(per_host)], per_host,
            args.rate, args.seconds, repeat, start_at, results[h], args.read_after)) for h in range(len(HOSTS))]
        for app in apps:
            app.start()
        time.sleep(max(0.0, start_at - time.perf_counter()))
        pids = [d.process.pid for d in setup.daemons]
        cpu0, wall0 = [cpu_seconds(pid) for pid in pids], time.perf_counter()
        time.sleep(args.seconds)
        cpu = [(cpu_seconds(pid) - c) / (time.perf_counter() - wall0) for pid, c in zip(pids, cpu0)]
        outcomes = [result.get(timeout=args.seconds + 120) for result in results]
        for app in apps:
            app.join()
        statuses = [d.status() for d in setup.daemons]
    finally:
        setup.close()
    late = [x for lateness, _ in outcomes for x in lateness]
    by_receiver = [[x for x in lateness] for lateness, _ in outcomes]
    links = [link for status in statuses for link in status["links"]]
    views = [view for status in statuses for view in status.get("network", {}).get("hosts", [])]
    return {"late": late, "by_app": by_receiver, "sent": sum(n for _, n in outcomes), "cpu": cpu,
            "drops": sum(link["drops"] for link in links if link["backend"] == "sim"),
            "heard_late": sum(v["late"] for v in views), "gaps": sum(v["gaps"] for v in views)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--links", type=int, default=50, help="links per host (the one daemon carries 4 x this)")
    parser.add_argument("--rate", type=float, default=10.0, help="frames per second per link")
    parser.add_argument("--seconds", type=float, default=20.0, help="of sending, per run")
    parser.add_argument("--repeats", type=int, default=2, help="runs of each side, alternating")
    add_application_timing(parser, WARM_UP_S)
    parser.add_argument("--loopback", action="store_true", help="4 daemons on loopback even where namespaces could be made")
    parser.add_argument("--realtime", action="store_true", help="every daemon with `hilgate run --realtime`")
    args = parser.parse_args()
    why = "--loopback" if args.loopback else netns.why_not()
    total = len(HOSTS) * args.links
    print(f"{len(HOSTS)} hosts x {args.links} links = {total} links on one channel, {args.rate:g} frames/s each "
          f"({total * args.rate:,.0f} frames/s offered), {args.seconds:g} s per run, {args.repeats} run(s) of each side, "
          f"alternating; one application process per host; nothing pinned; daemons "
          f"{'with --realtime' if args.realtime else 'at normal priority'}", flush=True)
    spaces = None
    if why is None:
        try:
            spaces = netns.Namespaces(len(HOSTS))
        except Exception as exc:  # (ip refused: e.g. no namespaces in this container)
            why = f"ip netns failed: {getattr(exc, 'stderr', '') or exc}".strip()
    print("4 daemons: " + ("one per network namespace, joined by veth pairs and a bridge (netns.py), TLS"
                          if spaces is not None else f"on loopback, TLS (namespaces not made: {why})"), flush=True)
    print(f"1 daemon: all {total} links, the scene without hosts", flush=True)
    sides = ["4 daemons", "1 daemon"]
    summary: dict[str, list[dict]] = {side: [] for side in sides}
    try:
        for repeat in range(1, args.repeats + 1):
            order = sides[(repeat - 1) % 2:] + sides[:(repeat - 1) % 2]
            for side in order:
                loadavg = os.getloadavg()[0]
                got = run(side, args, repeat, spaces)
                if not got["late"]:
                    raise RuntimeError(f"{side}: no delivery measured in run {repeat}")
                ms = [1e3 * x for x in got["late"]]
                p50, p99 = percentile(ms, 0.5), percentile(ms, 0.99)
                per_app = [(percentile(a, 0.5) * 1e3, percentile(a, 0.99) * 1e3) if a else (math.nan, math.nan)
                           for a in got["by_app"]]
                summary[side].append({"p50": p50, "p99": p99, "cpu": got["cpu"]})
                cpu = " ".join(f"{c:.2f}" for c in got["cpu"])
                print(f"run {repeat}, {side:>9}: lateness p50 {p50:.3f} ms  p99 {p99:.3f} ms  max {max(ms):.3f} ms; "
                      f"{len(ms):,} delivered of {got['sent']:,} sent; per application p50/p99 "
                      + ", ".join(f"{a:.2f}/{b:.2f}" for a, b in per_app)
                      + f" ms; daemon CPU s per wall s: {cpu} (sum {sum(got['cpu']):.2f}); dropped by the daemons "
                      f"{got['drops']}; heard late {got['heard_late']}, missing between hosts {got['gaps']}; "
                      f"load average {loadavg:.2f}", flush=True)
    finally:
        if spaces is not None:
            spaces.close()
    print("medians over the runs:")
    for side in sides:
        runs = summary[side]
        per_daemon = [statistics.median(r["cpu"][d] for r in runs) for d in range(len(runs[0]["cpu"]))]
        print(f"  {side:>9}: lateness p50 {statistics.median(r['p50'] for r in runs):.3f} ms, p99 "
              f"{statistics.median(r['p99'] for r in runs):.3f} ms (p99 {min(r['p99'] for r in runs):.3f}-"
              f"{max(r['p99'] for r in runs):.3f}); CPU per daemon " + " ".join(f"{c:.2f}" for c in per_daemon)
              + f" s per wall s, all daemons {statistics.median(sum(r['cpu']) for r in runs):.2f}", flush=True)


if __name__ == "__main__":
    main()
