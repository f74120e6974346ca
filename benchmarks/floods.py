#!/usr/bin/env python3
"""Floods against a daemon (issue 37), with figures: what an honest sender gets during each flood, what
the daemon's memory does, whether STATUS is answered.

Every case runs a real daemon on loopback with the lab's credentials (``hilgate network init`` in a
temporary directory) and an honest sender at its own pace (``--rate`` frames a second of 20 bytes, for
``--seconds``), first alone (the baseline), then while a flood runs from its first frame to its last:

1. **Zenoh door**: another application floods the same link with SENDs under its own credentials.
2. **ROS 2 door**: another process floods the link's ``send`` topic, one writer at 5 000 frames a second,
   then 32 writers as fast as they go (``tests/peers/dds_flooder.py``); the honest sender is a node of
   its own.
3. **Socket GLI**: another client of the same link's Unix socket sends as fast as it can, never waiting for
   READY (the socket GLI has no queue per client: frames go to the modem's FIFO as they come).
4. **Transmissions with a host's key**: a thief with a host's certificate puts 60 kB of garbage on that
   host's transmission key as fast as Zenoh takes it, at daemon A, while B's honest application sends
   to A: with host C's key (another host's flood: B's frames are handed to A's loop in their own turns),
   then with B's own (its frames and the flood share B's place in the hand-over, and are dropped alike).

The link is 20 000 b/s (a 20-byte frame 10 ms on air, a flood frame of 50 bytes 22 ms), so every flood
fills it.  Printed per case: the honest frames sent, received during the flood, the rate they crossed
at, their delay from send to receipt (p50, p95, max) and its lateness (the delay beyond the baseline's
p50); the daemon's memory (RSS at the start, the peak during the flood, after); STATUS asked over the
control socket all along (answered, and the slowest answer); the daemon's drops by cause.

    python benchmarks/floods.py [--seconds 10] [--rate 10] [--flood-margin 1] [--cases zenoh ros2 socket tx]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import socket
import subprocess
import sys
import tempfile
import threading
import time
import uuid

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
from ports import free_port  # noqa: E402  (ports outside the ephemeral range: tests/ports.py)
from daemon_harness import Daemon  # noqa: E402

from hilgate.client import Link  # noqa: E402
from hilgate.control_client import request  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DDS_FLOODER = os.path.join(REPO, "tests", "peers", "dds_flooder.py")
BITRATE = 20000
GARBAGE = 60_000


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as handle:
        for line in handle:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


def pct(samples: list[float], q: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


def scene(links: str, zenoh: str = "", extra: str = "") -> str:
    return (f"channels: {{ac: {{speed_mps: 1500}}}}\n{zenoh}"
            "vehicles: {va: {pose: {static: [0, 0, 0]}}, vb: {pose: {static: [10, 0, 0]}}}\n"
            f"links:\n{links}trace: {{poses_s: 0}}\n{extra}")


def link_line(name: str, vehicle: str, address: int, host: str = "", gli: str = ", gli: [socket]") -> str:
    """A link of the cases' scenes: no POSIX queues unless asked (no dccomms application here, and the
    user's queue budget is every run's on the machine)."""
    where = f", host: {host}" if host else ""
    return (f"  {name}: {{vehicle: {vehicle}, address: {address}, bitrate_bps: {BITRATE}, "
            f"addressing: strict{where}{gli}}}\n")


class Watch:
    """The daemon's memory and STATUS, on a thread of its own, while a flood runs."""

    def __init__(self, daemon: Daemon):
        self.daemon = daemon
        self.pid = daemon.process.pid
        self.start_mb = rss_mb(self.pid)
        self.peak_mb = self.start_mb
        self.asked = self.answered = 0
        self.slowest = 0.0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            self.peak_mb = max(self.peak_mb, rss_mb(self.pid))
            self.asked += 1
            began = time.monotonic()
            try:
                request({"class": "STATUS"}, self.daemon.runtime, timeout=30.0)
                self.answered += 1
            except (OSError, ValueError):
                pass
            self.slowest = max(self.slowest, time.monotonic() - began)
            self.stop.wait(0.05)

    def close(self) -> str:
        self.stop.set()
        self.thread.join()
        return (f"daemon RSS {self.start_mb:.0f} MB -> peak {self.peak_mb:.0f} MB (after {rss_mb(self.pid):.0f} MB); "
                f"STATUS answered {self.answered} of {self.asked} during the flood, slowest {self.slowest * 1e3:.0f} ms")


class Receiver:
    """The honest frames' arrival times, read from a socket client of the receiving link."""

    def __init__(self, link_id: str, runtime: str):
        self.link = Link.open(link_id, runtime_dir=runtime)
        self.arrived: dict[bytes, float] = {}
        self.flood = 0
        self.flooded = False  # (a flood has been started at this link)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            message = self.link.recv(timeout=0.2)
            if message is None:
                continue
            if message.data.startswith(b"honest"):
                self.arrived[bytes(message.data)] = time.monotonic()
            else:
                self.flood += 1

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.link.close()


def honest_run(send, receiver: Receiver, rate: float, seconds: float, tag: str) -> tuple[dict, float]:
    """Send ``rate`` frames a second for ``seconds`` through ``send(payload)``; the send times, and when
    sending ended."""
    sent: dict[bytes, float] = {}
    period = 1.0 / rate
    start = time.monotonic()
    for i in range(int(rate * seconds)):
        at = start + i * period
        delay = at - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        payload = b"honest %s %04d" % (tag.encode(), i)
        sent[payload] = time.monotonic()
        send(payload)
    return sent, time.monotonic()


def figures(label: str, sent: dict, receiver: Receiver, flood_end: float | None, baseline: float | None,
            seconds: float) -> tuple[str, float]:
    delays = [receiver.arrived[p] - t for p, t in sent.items() if p in receiver.arrived]
    during = sum(1 for p in sent if p in receiver.arrived and (flood_end is None or receiver.arrived[p] <= flood_end))
    p50 = pct(delays, 0.5)
    late = f"; lateness p50 {max(0.0, p50 - baseline) * 1e3:.0f} ms, max {max(0.0, max(delays) - baseline) * 1e3:.0f} ms" \
        if baseline is not None and delays else ""
    when = "during the flood" if flood_end is not None else "(no flood)"
    return (f"{label}: honest {during} of {len(sent)} frames received {when} ({during / seconds:.1f}/s of "
            f"{len(sent) / seconds:.1f}/s offered), delay p50 {p50 * 1e3:.0f} ms p95 {pct(delays, 0.95) * 1e3:.0f} ms "
            f"max {max(delays, default=float('nan')) * 1e3:.0f} ms{late}"), p50


def udp_receive_errors() -> int:
    """Datagrams the kernel dropped for want of room in a socket's receive buffer (this machine, every
    process): where a DDS flood loses samples before any reader sees them (then resent by DDS)."""
    with open("/proc/net/snmp") as handle:
        rows = [line.split() for line in handle if line.startswith("Udp:")]
    return int(rows[1][rows[0].index("RcvbufErrors")])


def drops(daemon: Daemon, link_id: str) -> dict:
    return next(l for l in daemon.status()["links"] if l["id"] == link_id)["drop_causes"]


def zenoh_session(port: int, identity: str):
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("connect/endpoints", json.dumps([f"tls/127.0.0.1:{port}"]))
    config.insert_json5("transport/link/tls", json.dumps({
        "root_ca_certificate": os.path.join(identity, "ca.pem"), "verify_name_on_connect": False,
        "connect_certificate": os.path.join(identity, "cert.pem"),
        "connect_private_key": os.path.join(identity, "key.pem"), "enable_mtls": True}))
    session = zenoh.open(config)
    deadline = time.monotonic() + 30
    while not list(session.info.peers_zid()) and time.monotonic() < deadline:
        time.sleep(0.05)
    return session


def flooding(put) -> tuple[threading.Event, threading.Thread, list[int]]:
    stop, count = threading.Event(), [0]

    def run() -> None:
        while not stop.is_set():
            put()
            count[0] += 1

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return stop, thread, count


RUNS = iter(range(1, 1000))


def settle(receiver: Receiver) -> None:
    """Wait until no flood frame has come for a second (what an earlier flood left queued has crossed);
    at once before the first flood."""
    if not receiver.flooded:
        return
    last, since = receiver.flood, time.monotonic()
    deadline = since + 120.0
    while time.monotonic() - since < 1.0 and time.monotonic() < deadline:
        time.sleep(0.1)
        if receiver.flood != last:
            last, since = receiver.flood, time.monotonic()


def crossed(sent: dict, receiver: Receiver, longest: float) -> None:
    """Wait for the honest frames still on their way: until every one has arrived, or ``longest`` seconds
    (one that has not arrived by then is not counted)."""
    deadline = time.monotonic() + longest
    while time.monotonic() < deadline and not all(p in receiver.arrived for p in sent):
        time.sleep(0.02)


def run_case(label: str, daemon: Daemon, send, receiver: Receiver, start_flood, link_id: str, args) -> None:
    """The baseline, then the same honest run during the flood ``start_flood()`` (which returns its stop);
    the flood runs alone ``args.flood_margin`` seconds before the honest run and after it."""
    run = next(RUNS)
    settle(receiver)
    sent, _ = honest_run(send, receiver, args.rate, args.seconds, f"{run}b")
    crossed(sent, receiver, 1.0)
    line, baseline = figures(f"{label}, baseline", sent, receiver, None, None, args.seconds)
    print(line, flush=True)
    watch = Watch(daemon)
    receiver.flooded = True
    stop = start_flood()
    time.sleep(args.flood_margin)  # the flood fills its queue first
    sent, _ = honest_run(send, receiver, args.rate, args.seconds, f"{run}f")
    time.sleep(args.flood_margin)  # (the last honest frames' time to cross, the flood still on)
    flood_end = time.monotonic()
    memory = watch.close()
    flood = stop()
    line, _ = figures(f"{label}, {flood}", sent, receiver, flood_end, baseline, args.seconds)
    print(line, flush=True)
    print(f"  {memory}; drops {drops(daemon, link_id)}", flush=True)


def case_zenoh(args, creds: str) -> None:
    from hilgate.gli.zenoh_door import link_key

    prefix, a, b, port = f"bench-{uuid.uuid4().hex[:8]}", f"fz{os.getpid()}a", f"fz{os.getpid()}b", free_port()
    zen = f"zenoh: {{prefix: {prefix}, credentials: {creds}}}\n"
    daemon = Daemon(scene(link_line(a, "va", 1) + link_line(b, "vb", 2), zen), (a, b),
                    ("--host", "solo", "--zenoh-listen", f"tls/127.0.0.1:{port}"), name="zenoh")
    try:
        receiver = Receiver(b, daemon.runtime)
        honest = Link.open(a, zenoh={"connect": [f"tls/127.0.0.1:{port}"], "prefix": prefix,
                                     "credentials": os.path.join(creds, "apps", "app-1")}, timeout=30)
        flooder = zenoh_session(port, os.path.join(creds, "apps", "app-2"))

        def start():
            import zenoh

            publisher = flooder.declare_publisher(link_key(prefix, "solo", a, "send/app-2"),
                                                  congestion_control=zenoh.CongestionControl.BLOCK)
            stop, thread, count = flooding(lambda: publisher.put(b"\x02" + b"F" * 50))

            def end() -> str:
                stop.set()
                thread.join()
                return f"another application flooding SENDs ({count[0]} sent)"
            return end

        run_case("zenoh door", daemon, lambda p: honest.send(p, dst=2), receiver, start, a, args)
        honest.close()
        flooder.close()
        receiver.close()
    finally:
        daemon.close()


def case_ros2(args) -> None:
    from hilgate.ros2.idl import message_class
    from hilgate.ros2.participant import Participant

    domain, ns = random.SystemRandom().randrange(0, 233), f"/b{uuid.uuid4().hex[:8]}"
    a, b = f"fr{os.getpid()}a", f"fr{os.getpid()}b"
    daemon = Daemon(scene(link_line(a, "va", 1, gli=", gli: [ros2]") + link_line(b, "vb", 2),
                          extra=f"ros2: {{domain_id: {domain}, namespace: {ns}}}\n"), (a, b), name="ros2")
    node = Participant(domain)
    Frame = message_class("hilgate_msgs/msg/Frame")
    writer = node.writer(f"{ns}/{a}/send", "hilgate_msgs/msg/Frame", depth=100)
    try:
        deadline = time.monotonic() + 30
        while not writer.get_publication_matched_status().current_count and time.monotonic() < deadline:
            time.sleep(0.05)
        receiver = Receiver(b, daemon.runtime)
        for writers, rate in ((1, 5000), (32, 0)):
            def start(writers=writers, rate=rate):
                udp = udp_receive_errors()
                flooder = subprocess.Popen([sys.executable, DDS_FLOODER, str(domain), f"{ns}/{a}/send",
                                            "--writers", str(writers), "--rate", str(rate), "--size", "50"],
                                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
                flooder.stdout.readline()  # matched

                def end() -> str:
                    flooder.stdin.close()
                    flooder.wait(30)
                    return (f"another process flooding with {writers} writer{'s' if writers > 1 else ''} "
                            f"{'at %d frames/s' % rate if rate else 'as fast as they go'}, "
                            f"{udp_receive_errors() - udp} UDP datagrams dropped by the kernel meanwhile")
                return end

            run_case("ros2 door", daemon, lambda p: writer.write(Frame(dst=2, data=p)), receiver, start, a, args)
        receiver.close()
    finally:
        node.close()
        daemon.close()


def case_socket(args) -> None:
    a, b = f"fs{os.getpid()}a", f"fs{os.getpid()}b"
    daemon = Daemon(scene(link_line(a, "va", 1) + link_line(b, "vb", 2)), (a, b), name="socket")
    try:
        receiver = Receiver(b, daemon.runtime)
        honest = Link.open(a, runtime_dir=daemon.runtime)

        def start():
            from hilgate.gli import wire

            flooder = socket.socket(socket.AF_UNIX)
            flooder.connect(os.path.join(daemon.runtime, "gli", f"{a}.sock"))
            flooder.sendall(wire.encode_json(wire.HELLO, {"link": a}))
            message = wire.encode_send(2, b"F" * 50)
            stop, thread, count = flooding(lambda: flooder.sendall(message * 16))

            def drain() -> None:  # (the flooder reads what the daemon says, so it is never disconnected as slow)
                flooder.settimeout(0.2)
                while not stop.is_set():
                    try:
                        flooder.recv(65536)
                    except OSError:
                        pass

            reader = threading.Thread(target=drain, daemon=True)
            reader.start()

            def end() -> str:
                stop.set()
                thread.join()
                reader.join()
                flooder.close()
                return f"another client flooding the socket, never waiting for READY ({count[0] * 16} SENDs)"
            return end

        run_case("socket GLI", daemon, lambda p: honest.send(p, dst=2), receiver, start, a, args)
        honest.close()
        receiver.close()
    finally:
        daemon.close()


def case_tx(args, creds: str) -> None:
    from hilgate.daemon import netcodec

    prefix, a, b = f"bench-{uuid.uuid4().hex[:8]}", f"ft{os.getpid()}a", f"ft{os.getpid()}b"
    ports = [free_port(), free_port()]
    zen = f"zenoh: {{prefix: {prefix}, credentials: {creds}, lease_s: 5}}\n"
    text = scene(link_line(a, "va", 1, host="A") + link_line(b, "vb", 2, host="B"), zen)
    A = Daemon(text, (a,), ("--host", "A", "--zenoh-listen", f"tls/127.0.0.1:{ports[0]}"), name="A")
    B = None
    try:
        B = Daemon(text, (b,), ("--host", "B", "--zenoh-listen", f"tls/127.0.0.1:{ports[1]}",
                                "--zenoh-connect", f"tls/127.0.0.1:{ports[0]}"), name="B")
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not all(
                any(h["state"] == "up" for h in d.status()["network"]["hosts"]) for d in (A, B)):
            time.sleep(0.1)
        receiver = Receiver(a, A.runtime)
        honest = Link.open(b, runtime_dir=B.runtime)
        garbage = bytes([netcodec.VERSION]) + os.urandom(GARBAGE - 1)
        for host in ("C", "B"):
            thief = zenoh_session(ports[0], os.path.join(creds, "hosts", host))

            def start(thief=thief, host=host):
                import zenoh

                publisher = thief.declare_publisher(f"{prefix}/tx/{host}/ac",
                                                    congestion_control=zenoh.CongestionControl.BLOCK)
                stop, thread, count = flooding(lambda: publisher.put(garbage))

                def end() -> str:
                    stop.set()
                    thread.join()
                    return f"a thief with {host}'s key putting 60 kB of garbage ({count[0]} messages)"
                return end

            run_case("B's frames at A", A, lambda p: honest.send(p, dst=1), receiver, start, a, args)
            print(f"  A's network counters {A.status()['network']['counters']}", flush=True)
            thief.close()
        honest.close()
        receiver.close()
    finally:
        if B is not None:
            B.close()
        A.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="the honest sender's run, alone and during a flood")
    parser.add_argument("--rate", type=float, default=10.0, help="the honest sender's frames a second")
    parser.add_argument("--flood-margin", type=float, default=1.0,
                        help="seconds the flood runs alone before the honest run (filling its queue) and after it")
    parser.add_argument("--cases", nargs="+", default=["zenoh", "ros2", "socket", "tx"],
                        choices=["zenoh", "ros2", "socket", "tx"])
    args = parser.parse_args()
    from hilgate.commands.credentials import init_network

    print(f"honest sender: {args.rate:g} frames/s of 20 bytes for {args.seconds:g} s, alone then during each flood; "
          f"links of {BITRATE} b/s; load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    with tempfile.TemporaryDirectory(prefix="hilgate-floods-") as scratch:
        creds = os.path.join(scratch, "creds")
        init_network(creds, ["solo", "A", "B", "C"], 2)
        for case in args.cases:
            if case == "zenoh":
                case_zenoh(args, creds)
            elif case == "ros2":
                case_ros2(args)
            elif case == "socket":
                case_socket(args)
            else:
                case_tx(args, creds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
