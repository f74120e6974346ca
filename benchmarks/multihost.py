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

Bare, TLS and plain round trips alternate, ``--repeats`` times; the ratio (TLS against bare) is printed as
min/median/max.

    python benchmarks/multihost.py [--round-trips 2000] [--frames 20000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gli_roundtrip import MESSAGE, _echo, frame, open_queue, percentiles, send_paced  # noqa: E402

from hilgate.gli.queues import unlink_queues  # noqa: E402

WARM_UP = 100
SPAWN = mp.get_context("spawn")  # never fork a process that has a Zenoh runtime


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


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


def _pong(port: int, key: str, ready) -> None:
    import zenoh

    session = zenoh.open(zenoh_config(listen=f"tcp/127.0.0.1:{port}"))
    publisher = session.declare_publisher(f"{key}/pong")
    session.declare_subscriber(f"{key}/ping", lambda sample: publisher.put(sample.payload.to_bytes()))
    ready.set()
    time.sleep(3600)


def bare(count: int) -> list[float]:
    import zenoh

    port, key = free_port(), f"bench-{uuid.uuid4().hex[:8]}"
    ready = SPAWN.Event()
    process = SPAWN.Process(target=_pong, args=(port, key, ready), daemon=True)
    process.start()
    ready.wait(30)
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
            raise RuntimeError("the bare ping-pong lost a message")
        samples.append(time.perf_counter() - start)
    session.close()
    process.terminate()
    process.join()
    return samples[WARM_UP:]


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
    """Daemons A and B, joined over loopback TCP."""

    def __init__(self, a: str, b: str, template: str = SCENE, secure: bool = True):
        from hilgate.netinit import init_network

        self.dir = tempfile.mkdtemp(prefix="hilgate-multihost-bench-")
        scene = os.path.join(self.dir, "scene.yaml")
        if secure:
            init_network(os.path.join(self.dir, "creds"), ["A", "B"], 1)
        security = f"credentials: {os.path.join(self.dir, 'creds')}" if secure else "insecure: true"
        with open(scene, "w") as handle:
            handle.write(template.format(a=a, b=b, prefix=f"bench-{uuid.uuid4().hex[:8]}", security=security))
        port = free_port()
        scheme = "tls" if secure else "tcp"
        self.processes = []
        for host, args in (("A", ["--zenoh-listen", f"{scheme}/127.0.0.1:{port}"]),
                           ("B", ["--zenoh-connect", f"{scheme}/127.0.0.1:{port}"])):
            notify_path = os.path.join(self.dir, f"notify-{host}")
            notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
            notify.bind(notify_path)
            with open(os.path.join(self.dir, f"{host}.log"), "w") as log:  # (the daemons' logs stay there)
                self.processes.append(subprocess.Popen(
                    [sys.executable, "-m", "hilgate", "run", scene, "--host", host, "--runtime-dir",
                     os.path.join(self.dir, host), "--no-status-line", *args],
                    env=dict(os.environ, NOTIFY_SOCKET=notify_path), stdout=log, stderr=subprocess.STDOUT))
            notify.settimeout(30)
            while b"READY=1" not in notify.recv(4096):
                pass
            notify.close()
        self.links = (a, b)
        deadline = time.monotonic() + 30
        while not self._sees("A", "B"):
            if time.monotonic() > deadline:
                raise RuntimeError("the daemons did not meet")
            time.sleep(0.05)

    def status(self, host: str) -> dict:
        with socket.socket(socket.AF_UNIX) as sock:
            sock.connect(os.path.join(self.dir, host, "control.sock"))
            reader = sock.makefile("r")
            reader.readline()
            sock.sendall(b'{"class": "STATUS"}\n')
            return json.loads(reader.readline())

    def _sees(self, host: str, other: str) -> bool:
        views = self.status(host)["network"]["hosts"]
        return any(v["host"] == other and v["state"] == "up" for v in views)

    def close(self) -> None:
        for process in self.processes:
            process.terminate()
            process.wait()
        unlink_queues(self.links)


def through_hilgate(count: int, secure: bool = True) -> list[float]:
    a, b = f"mha{os.getpid()}", f"mhb{os.getpid()}"
    network = Network(a, b, secure=secure)
    try:
        result = SPAWN.Queue()
        echo = SPAWN.Process(target=_echo, args=(b, count + WARM_UP, "echo", result))
        echo.start()
        tx, rx = open_queue(f"/{a}_tx_dlnk_phy"), open_queue(f"/{a}_rx_dlnk_phy")
        message = frame(b"\xa5" * 2048, 0, 2)
        assert len(message) == MESSAGE
        samples = []
        for _ in range(count + WARM_UP):
            start = time.perf_counter()
            tx.send(message)
            while True:
                reply, _ = rx.receive(10.0)
                if reply[0] == 0:
                    break
            samples.append(time.perf_counter() - start)
        echo.join()
        tx.close()
        rx.close()
        return samples[WARM_UP:]
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
        result = SPAWN.Queue()
        counter = SPAWN.Process(target=_echo, args=(b, count, "count", result))
        counter.start()
        time.sleep(1.0)  # (the counter is up and has said REQ_STATE)
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--round-trips", type=int, default=2000)
    parser.add_argument("--frames", type=int, default=20000)
    parser.add_argument("--size", type=int, default=20, help="payload bytes per frame in the throughput test")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--on-time", type=int, default=100, help="frames for the wall-clock delivery check")
    args = parser.parse_args()
    ratios, bares, hils, plains = [], [], [], []
    for repeat in range(args.repeats):
        bare_p50, bare_p99 = percentiles(bare(args.round_trips))
        hil_p50, hil_p99 = percentiles(through_hilgate(args.round_trips, secure=True))
        plain_p50, plain_p99 = percentiles(through_hilgate(args.round_trips, secure=False))
        bares.append(bare_p50)
        hils.append(hil_p50)
        plains.append(plain_p50)
        ratios.append(hil_p50 / bare_p50)
        print(f"repeat {repeat + 1}: bare Zenoh ping-pong p50 {bare_p50 * 1e6:.0f} µs (p99 {bare_p99 * 1e6:.0f}); "
              f"through two daemons, TLS p50 {hil_p50 * 1e6:.0f} µs (p99 {hil_p99 * 1e6:.0f}), "
              f"insecure p50 {plain_p50 * 1e6:.0f} µs (p99 {plain_p99 * 1e6:.0f}); "
              f"ratio TLS/bare {hil_p50 / bare_p50:.2f}", flush=True)
    print(f"round trip of a {MESSAGE}-byte frame, p50: bare {statistics.median(bares) * 1e6:.0f} µs, hilgate "
          f"with TLS {statistics.median(hils) * 1e6:.0f} µs, insecure {statistics.median(plains) * 1e6:.0f} µs "
          f"(median of {args.repeats}; TLS costs {(statistics.median(hils) - statistics.median(plains)) * 1e6:+.0f} µs); "
          f"ratio TLS/bare min/median/max {min(ratios):.2f} / {statistics.median(ratios):.2f} / {max(ratios):.2f} "
          f"(target <= 3)")
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
