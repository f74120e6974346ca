#!/usr/bin/env python3
"""Across hosts: a GLI frame through two daemons joined over Zenoh, against a bare Zenoh ping-pong.

1. Bare: two processes bounce a 2 066-byte message over Zenoh (peer mode, loopback TCP, no scouting).
2. hilgate: daemon A and daemon B (two processes, their own runtime directories and Zenoh ports),
   one link each on an ideal channel (same place, 1e12 bit/s, no delays), joined as shipped (mutual
   TLS with credentials from ``hilgate network init``, Zenoh's access control) and, in the same run,
   ``insecure`` (plain TCP): what authentication costs the round trip.  A dccomms-layout
   application on A's queue sends a 2 066-byte queue message (a 2 048-byte VariableLength2B payload)
   to B's link; an echo application on B sends it back: app → A → Zenoh → B → app → B → Zenoh → A →
   app.  Target: p50 ≤ 3 × the bare ping-pong.  (With no propagation delay every frame from the other
   host is "late": the daemons deliver it at once and count it, as they must.)
3. On time: an application on A sends to one on B over an acoustic channel (150 m, 1000 b/s); the
   wall-clock time to delivery minus the model's (target within −2 / +20 ms).
4. Throughput: the application on A sends 20-byte payloads at 5 000 and 10 000 a second and as fast
   as its queue takes them, the one on B counts; frames per second and frames lost, by cause
   (target ≥ 5 000 frames/s, zero loss).

The round trips (1 and 2) are pinned (``placement.py``), in two placements: **same CPU** (every process
on one CPU) and **across CPUs** (the client and daemon B on one, daemon A and B's echo on the other, so
each of the six hops crosses; the bare ping and pong on one each).  Bare, TLS and insecure alternate:
each goes first in turn from one repeat to the next, and so does each placement; ``--repeats`` runs of
each per placement.  Printed per placement: each side's p50 and the ratios TLS/bare and insecure/bare,
min/median/max over the repeats.  The bare ping-pong is the peer baseline
/work/shared/peers/zenoh_pingpong.py's (the same configuration and message), with a free port and a key
of its own so that two runs on one machine do not meet, and its ping in a process of its own so that it
can be pinned.  3 and 4 are not pinned (they say so) and run with TLS.

    python benchmarks/multihost.py [--round-trips 2000] [--frames 20000 (0: the round trips alone)] [--repeats 3] [--placement same|across|both]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import statistics
import sys
import tempfile
import threading
import time
import uuid

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
from ports import free_port  # noqa: E402  (ports outside the ephemeral range: tests/ports.py)
from gli_roundtrip import MESSAGE, _echo, frame, open_queue, percentiles, round_trip, send_paced  # noqa: E402
from peers import spread  # noqa: E402
from daemon_harness import Daemon  # noqa: E402
from placement import Placement, choose, pin, pinned  # noqa: E402

from hilgate.gli.queues import unlink_queues  # noqa: E402

WARM_UP = 100
SPAWN = mp.get_context("spawn")  # never fork a process that has a Zenoh runtime


def zenoh_config(listen: str | None = None, connect: str | None = None):
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", json.dumps([listen or "tcp/127.0.0.1:0"]))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps([connect]))
    return config


# -- 1. bare Zenoh ping-pong ------------------------------------------------------------------------


def _pong(port: int, key: str, ready, cpu: int | None) -> None:
    pin(cpu)  # before the session: Zenoh's threads stay on this CPU too
    import zenoh

    session = zenoh.open(zenoh_config(listen=f"tcp/127.0.0.1:{port}"))
    publisher = session.declare_publisher(f"{key}/pong")
    session.declare_subscriber(f"{key}/ping", lambda sample: publisher.put(sample.payload.to_bytes()))
    ready.set()
    time.sleep(3600)


def _ping(port: int, key: str, count: int, cpu: int | None, result) -> None:
    pin(cpu)
    import zenoh

    session = zenoh.open(zenoh_config(connect=f"tcp/127.0.0.1:{port}"))
    got = threading.Event()
    session.declare_subscriber(f"{key}/pong", lambda sample: got.set())
    publisher = session.declare_publisher(f"{key}/ping")
    while not list(session.info.peers_zid()):
        time.sleep(0.01)
    time.sleep(0.5)
    message = bytes(MESSAGE)
    samples = []
    for _ in range(count + WARM_UP):
        got.clear()
        start = time.perf_counter()
        publisher.put(message)
        if not got.wait(5):
            result.put("the bare ping-pong lost a message")
            return
        samples.append(time.perf_counter() - start)
    session.close()
    result.put(samples[WARM_UP:])


def bare(count: int, placement: Placement) -> list[float]:
    """Ping and pong, each in a process of its own (as /work/shared/peers/zenoh_pingpong.py, the peer
    baseline, with a free port and a key of its own), on the placement's steps 0 and 1."""
    port, key = free_port(), f"bench-{uuid.uuid4().hex[:8]}"
    ready, result = SPAWN.Event(), SPAWN.Queue()
    pong = SPAWN.Process(target=_pong, args=(port, key, ready, placement.cpu(1)), daemon=True)
    pong.start()
    try:
        if not ready.wait(60):
            raise RuntimeError("the bare pong process did not start")
        ping = SPAWN.Process(target=_ping, args=(port, key, count, placement.cpu(0), result))
        ping.start()
        samples = result.get(timeout=300)
        ping.join()
    finally:
        pong.terminate()
        pong.join()
    if isinstance(samples, str):
        raise RuntimeError(samples)
    return samples


# -- 2. and 3. through two daemons --------------------------------------------------------------------


SCENE = """\
name: multihost-bench
channels: {{ideal: {{speed_mps: 3.0e8}}}}
zenoh: {{prefix: {prefix}, {security}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links:
  {a}: {{vehicle: v, host: A, address: 1, bitrate_bps: 1.0e12, fifo_bytes: 10000000, packet: vl2b}}
  {b}: {{vehicle: v, host: B, address: 2, bitrate_bps: 1.0e12, fifo_bytes: 10000000, packet: vl2b}}
"""


class Network:
    """Daemons A and B, joined over loopback TCP (``secure``: mutual TLS); A pinned to ``cpus[0]``, B to
    ``cpus[1]`` (None: the kernel's choice)."""

    def __init__(self, a: str, b: str, template: str = SCENE, secure: bool = True,
                 cpus: tuple[int | None, int | None] = (None, None)):
        from hilgate.commands.credentials import init_network

        self.dir = tempfile.mkdtemp(prefix="hilgate-multihost-bench-")
        self.links = (a, b)
        if secure:
            init_network(os.path.join(self.dir, "creds"), ["A", "B"], 1)
        security = f"credentials: {os.path.join(self.dir, 'creds')}" if secure else "insecure: true"
        text = template.format(a=a, b=b, prefix=f"bench-{uuid.uuid4().hex[:8]}", security=security)
        port = free_port()
        scheme = "tls" if secure else "tcp"
        self.daemons: dict[str, Daemon] = {}
        try:
            for host, cpu, args in (("A", cpus[0], ["--zenoh-listen", f"{scheme}/127.0.0.1:{port}"]),
                                    ("B", cpus[1], ["--zenoh-connect", f"{scheme}/127.0.0.1:{port}"])):
                self.daemons[host] = Daemon(text, args=("--host", host, *args), cpu=cpu, directory=self.dir,
                                            name=host)
            deadline = time.monotonic() + 30
            while not self._sees("A", "B"):
                if time.monotonic() > deadline:
                    raise RuntimeError("the daemons did not meet")
                time.sleep(0.05)
        except BaseException:
            self.close()
            raise

    def status(self, host: str) -> dict:
        return self.daemons[host].status()

    def heard(self, host: str, other: str) -> tuple[int, float]:
        """How many transmissions of ``other`` daemon ``host`` took, and their summed delay (s): from the
        model time ``other`` put each on air (its loop reading the application's frame) to the model
        time ``host``'s loop took its message (the daemons' own ``net_delay_mean_ms``, to 1 µs)."""
        view = next(v for v in self.status(host)["network"]["hosts"] if v["host"] == other)
        return view["heard"], (view["net_delay_mean_ms"] or 0.0) * 1e-3 * view["heard"]

    def _sees(self, host: str, other: str) -> bool:
        views = self.status(host)["network"]["hosts"]
        return any(v["host"] == other and v["state"] == "up" for v in views)

    def close(self) -> None:
        for daemon in self.daemons.values():
            daemon.close()
        unlink_queues(self.links)


def through_hilgate(count: int, placement: Placement, secure: bool = True) -> tuple[list[float], tuple[float, float]]:
    """The client (this thread) on the placement's step 0, daemon A on 1, daemon B on 2, B's echo on 3.
    Returns the round trips and the mean delay A → B and B → A over them (:meth:`Network.heard`: the
    sending daemon's pass, the encoding, Zenoh and the hand-over to the receiving daemon's loop).
    Each direction carries the offset between the daemons' epochs (±10 µs); their sum does not."""
    a, b = f"mha{os.getpid()}", f"mhb{os.getpid()}"
    network = Network(a, b, secure=secure, cpus=(placement.cpu(1), placement.cpu(2)))
    try:
        result = SPAWN.Queue()
        echo = SPAWN.Process(target=_echo, args=(b, count + WARM_UP, "echo", result, 10.0, placement.cpu(3)))
        echo.start()
        tx, rx = open_queue(f"/{a}_tx_dlnk_phy"), open_queue(f"/{a}_rx_dlnk_phy")
        message = frame(b"\xa5" * 2048, 0, 2)
        assert len(message) == MESSAGE
        samples = []
        heard = []  # (the daemons asked after the warm-up and at the end: between round trips)
        with pinned(placement.cpu(0)):
            for i in range(count + WARM_UP):
                if i == WARM_UP:
                    heard.append((network.heard("B", "A"), network.heard("A", "B")))
                samples.append(round_trip(tx, rx, message, 10.0))
        heard.append((network.heard("B", "A"), network.heard("A", "B")))
        echo.join()
        tx.close()
        rx.close()
        (ab0, ba0), (ab1, ba1) = heard
        delays = tuple((end[1] - begin[1]) / max(1, end[0] - begin[0]) for begin, end in ((ab0, ab1), (ba0, ba1)))
        return samples[WARM_UP:], delays
    finally:
        network.close()


def throughput(count: int, size: int, rate: float | None) -> tuple[float, int, int, int]:
    """Frames per second the application on B saw, frames lost, frames the daemons counted as dropped,
    frames missing between the hosts.  ``rate`` paces the sender (sleeping, not spinning; None: as fast
    as its queue takes them: then nothing slows A down to what B's application reads, as an ideal
    1e12 b/s channel would not, and B's queue overflows)."""
    a, b = f"mta{os.getpid()}", f"mtb{os.getpid()}"
    network = Network(a, b)
    try:
        result, said = SPAWN.Queue(), SPAWN.Event()
        counter = SPAWN.Process(target=_echo, args=(b, count, "count", result), kwargs={"said": said})
        counter.start()
        if not said.wait(60):
            raise RuntimeError("the counter did not start")
        start = send_paced(a, count, size, rate)
        received, first, last = result.get(timeout=120)
        counter.join()
        links = network.status("A")["links"] + network.status("B")["links"]
        drops = sum(link["drops"] + link["unread"] for link in links)
        gaps = sum(view["gaps"] for view in network.status("B")["network"]["hosts"])
        return received / (last - start), count - received, drops, gaps
    finally:
        network.close()


ACOUSTIC = """\
name: multihost-on-time
channels: {{ac: {{speed_mps: 1500}}}}
zenoh: {{prefix: {prefix}, {security}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {{static: [150, 0, 0]}}}}
links:
  {a}: {{vehicle: va, host: A, address: 1, bitrate_bps: 1000, packet: vl2b, addressing: strict}}
  {b}: {{vehicle: vb, host: B, address: 2, bitrate_bps: 1000, packet: vl2b, addressing: strict}}
"""


def on_time(count: int) -> list[float]:
    """Wall-clock delivery error (s) of frames from an application on A to one on B, 150 m apart at
    1000 b/s: when the application on B has the frame, minus when the one on A sent it, minus the
    model's air time and propagation delay."""
    from hilgate.client import Link

    a, b = f"moa{os.getpid()}", f"mob{os.getpid()}"
    network = Network(a, b, ACOUSTIC)
    try:
        errors = []
        with Link.open(a, runtime_dir=os.path.join(network.dir, "A")) as la, \
                Link.open(b, runtime_dir=os.path.join(network.dir, "B")) as lb:
            payload = b"on time?"
            model = (1 + 2 + len(payload) + 2) * 8 / 1000 + 150 / 1500
            for _ in range(count):
                start = time.perf_counter()
                la.send(payload, dst=2)
                message = lb.recv(timeout=10)
                errors.append(time.perf_counter() - start - model)
                assert message is not None and message.data == payload
                time.sleep(0.05)
        return errors
    finally:
        network.close()


SIDES = {"bare": "bare Zenoh", "tls": "hilgate, TLS", "insecure": "hilgate, insecure"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--round-trips", type=int, default=2000)
    parser.add_argument("--frames", type=int, default=20000)
    parser.add_argument("--size", type=int, default=20, help="payload bytes per frame in the throughput test")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each side per placement, alternating")
    parser.add_argument("--placement", choices=("same", "across", "both"), default="both")
    parser.add_argument("--on-time", type=int, default=100, help="frames for the wall-clock delivery check")
    args = parser.parse_args()
    chosen, why_not = choose(args.placement)
    for placement in chosen:
        print(f"{placement.name:>11}: {placement.describe(['client', 'daemon A', 'daemon B', 'echo'])} "
              f"(bare: {placement.describe(['ping', 'pong'])})", flush=True)
    if why_not:
        print(why_not, flush=True)
    runs = {"bare": lambda n, p: (bare(n, p), None), "tls": lambda n, p: through_hilgate(n, p, secure=True),
            "insecure": lambda n, p: through_hilgate(n, p, secure=False)}
    sides = list(SIDES)
    p50s: dict[tuple[str, str], list[float]] = {}
    shares: dict[tuple[str, str], list[tuple[float, float]]] = {}  # (mean round trip, A → B + B → A)
    for repeat in range(1, args.repeats + 1):
        for k in range(len(chosen)):
            placement = chosen[(repeat - 1 + k) % len(chosen)]  # each placement goes first in turn
            order = sides[(repeat - 1) % 3:] + sides[:(repeat - 1) % 3]  # and each side, from one repeat to the next
            got, delays = {}, {}
            for side in order:
                samples, delays[side] = runs[side](args.round_trips, placement)
                got[side] = percentiles(samples)
                p50s.setdefault((placement.name, side), []).append(got[side][0])
                if delays[side] is not None:
                    shares.setdefault((placement.name, side), []).append((statistics.fmean(samples), sum(delays[side])))
            print(f"repeat {repeat}, {placement.name:>11}: " + "; ".join(
                f"{SIDES[side]} p50 {got[side][0] * 1e6:.0f} µs (p99 {got[side][1] * 1e6:.0f})" for side in sides)
                + f"; ratio TLS/bare {got['tls'][0] / got['bare'][0]:.2f}, insecure/bare "
                f"{got['insecure'][0] / got['bare'][0]:.2f}; order: {', '.join(order)}; mean A -> B / B -> A: "
                + ", ".join(f"{side} {delays[side][0] * 1e6:.0f} / {delays[side][1] * 1e6:.0f} µs" for side in ("tls", "insecure")),
                flush=True)
    print(f"round trip of a {MESSAGE}-byte frame, p50, {args.round_trips:,} round trips x {args.repeats} per placement, "
          f"min / median / max over the repeats:")
    for placement in chosen:
        got = {side: p50s[(placement.name, side)] for side in sides}
        tls = [t / b for t, b in zip(got["tls"], got["bare"])]
        plain = [t / b for t, b in zip(got["insecure"], got["bare"])]
        cost = [1e6 * (t - i) for t, i in zip(got["tls"], got["insecure"])]
        print(f"  {placement.name:>11}: " + ", ".join(
            f"{SIDES[side]} {spread([1e6 * v for v in got[side]], 0)} µs" for side in sides)
            + f"; ratio TLS/bare {spread(tls)}, insecure/bare {spread(plain)}; TLS costs {spread(cost, 0)} µs", flush=True)
    print("(target: <= 3 x bare Zenoh at p50, with TLS)")
    print("where hilgate's round trip goes, means, min / median / max over the repeats: from one daemon reading the "
          "frame to the other's loop taking its message, both ways (the sender's pass, encoding, Zenoh, the hand-over "
          "to the loop; the daemons' own net_delay), and the rest (the receivers' passes, four queue hops, the echo):")
    for placement in chosen:
        for side in ("tls", "insecure"):
            pairs = shares[(placement.name, side)]
            print(f"  {placement.name:>11}, {side:>8}: round trip {spread([1e6 * m for m, _ in pairs], 0)} µs = "
                  f"both ways {spread([1e6 * n for _, n in pairs], 0)} µs + the rest "
                  f"{spread([1e6 * (m - n) for m, n in pairs], 0)} µs", flush=True)
    if args.frames <= 0:
        return  # (--frames 0: the round trips alone)
    print("delivery on the wall clock and throughput: unpinned (the kernel places the daemons and applications); "
          "both with TLS", flush=True)
    errors = sorted(on_time(args.on_time))
    print(f"delivery on the wall clock A -> B (150 m, 1000 b/s), application to application, minus the model: "
          f"min {errors[0] * 1e3:+.2f} ms, p50 {errors[len(errors) // 2] * 1e3:+.2f} ms, "
          f"p99 {errors[int(0.99 * (len(errors) - 1))] * 1e3:+.2f} ms, max {errors[-1] * 1e3:+.2f} ms "
          f"(target within -2 / +20 ms)", flush=True)
    for offered in (5000, 10000, None):
        rate, lost, drops, gaps = throughput(args.frames, args.size, offered)
        label = f"{offered:,}/s offered" if offered else "flat out"
        print(f"throughput A -> B, {args.size}-byte payloads, {label:>16}: {rate:,.0f} frames/s received, {lost} lost, "
              f"{drops} dropped by the daemons, {gaps} missing between the hosts", flush=True)
    print("(target >= 5,000 frames/s with zero loss)")


if __name__ == "__main__":
    main()
