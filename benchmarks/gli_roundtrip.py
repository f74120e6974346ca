#!/usr/bin/env python3
"""GLI round trip and throughput through the daemon, against a bare POSIX-queue ping-pong and a bare
Python relay.

1. Bare: two processes bounce a 2066-byte message over two queues (two hops per round trip).
1b. A bare Python relay: the least any Python daemon can do for the dccomms protocol on this machine.
   One process (pinned where the daemon is) waits in ``epoll`` on links a's and b's tx queues, takes
   the message, checks its vl2b CRC, puts it as it is in the other link's rx queue and READY in the
   sender's (and answers REQ_STATE with READY): the same clients, the same four queue hops and two
   READY messages as through hilgate, and no model, no router, no trace.  Hilgate's added latency
   minus the relay's is what hilgate's own design costs; the relay's added latency is the floor of
   any Python daemon here.
2. hilgate: the daemon (a subprocess) with two links on an ideal channel (same place, 1e12 bit/s,
   no delays); a dccomms-layout application on link a sends a VariableLength2BPacket to link b, an
   echo application on b sends it back: app → hilgate → app → hilgate → app, four queue hops.
   Target (DESIGN.md): ≤ 40 µs added to the bare round trip at p50 (2× is the ratio's floor: twice the hops).
3. Throughput: the application on a sends frames at 5 000, 10 000 and 20 000 a second (paced by
   sleeping, never spinning: on a 2-core machine a spinning sender takes the daemon's core) and as
   fast as its queue takes them, the one on b counts them; frames per second and the number lost
   (target: zero loss up to 20 000 frames/s).

Every process of a round trip is pinned (``placement.py``), in two placements measured one after the
other: **same CPU** (the client, the daemon and the echo on one CPU) and **across CPUs** (client and echo on
one, the daemon on the other, so each of the four hops crosses; the bare ping-pong likewise, each of its two
hops crossing).  Unpinned, the kernel draws one of these per run for the anchor and another for hilgate,
and the difference of the two is a lottery (8 µs against 50 µs for the bare ping-pong on a 2-core virtual
machine).  Bare, relay and hilgate take turns (each goes first in turn), ``--repeats`` times per placement,
in this one run.  The **added latency** is hilgate's (or the relay's) round trip minus the bare one of the
same repeat and placement, at p50 and at p99, in µs: min/median/max over the repeats; "beyond the relay"
is hilgate's round trip minus the relay's.  The throughput runs are not pinned
(and say so): they measure how much the daemon carries wherever the kernel puts it.  Every queue handle is
closed (a daemon's queues count against the per-user budget until the last handle goes).

    python benchmarks/gli_roundtrip.py [--round-trips 3000] [--frames 20000 (0: no throughput)] [--repeats 3] [--placement same|across|both]
"""

from __future__ import annotations

import argparse
import binascii
import multiprocessing as mp
import os
import select
import statistics
import struct
import sys
import threading
import time

import posix_ipc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from daemon_harness import Daemon  # noqa: E402
from placement import Placement, choose, pin, pinned  # noqa: E402

from hilgate.gli.queues import unlink_queues  # noqa: E402

MESSAGE = 2066
MAX_REAL = 2053
WARM_UP = 100


def frame(payload: bytes, seq: int, dst: int) -> bytes:
    real = b"\x55" + len(payload).to_bytes(2, "big") + payload + binascii.crc_hqx(payload, 0).to_bytes(2, "big")
    return b"\x00" + real.ljust(MAX_REAL, b"\0") + struct.pack("<III", seq, 0, dst)


def open_queue(name: str) -> posix_ipc.MessageQueue:
    return posix_ipc.MessageQueue(name, posix_ipc.O_CREAT, 0o666, 10, 8192)


def percentiles(samples: list[float]) -> tuple[float, float]:
    ordered = sorted(samples)
    return ordered[len(ordered) // 2], ordered[int(0.99 * (len(ordered) - 1))]


# -- 1. bare ping-pong ---------------------------------------------------------------------------


def _pong(ping_name: str, pong_name: str, count: int, cpu: int | None) -> None:
    pin(cpu)
    ping, pong = open_queue(ping_name), open_queue(pong_name)
    for _ in range(count):
        message, _ = ping.receive()
        pong.send(message)
    ping.close()
    pong.close()


def bare(count: int, placement: Placement) -> list[float]:
    """Ping (this thread) on the placement's step 0, pong on step 1."""
    tag = f"/hgbench{os.getpid()}"
    ping, pong = open_queue(tag + "_ping"), open_queue(tag + "_pong")
    process = mp.Process(target=_pong, args=(tag + "_ping", tag + "_pong", count, placement.cpu(1)))
    process.start()
    message = b"\x00" * MESSAGE
    samples = []
    with pinned(placement.cpu(0)):
        for _ in range(count):
            start = time.perf_counter()
            ping.send(message)
            pong.receive()
            samples.append(time.perf_counter() - start)
    process.join()
    for queue in (ping, pong):
        queue.close()
        queue.unlink()
    return samples[WARM_UP:]


# -- 1b. a bare Python relay ---------------------------------------------------------------------


READY_MESSAGE = b"\x02\x01"  # CMD_STATE READY


def _relay(a: str, b: str, frames: int, cpu: int | None, up) -> None:
    """Relay ``frames`` FRAME messages between links ``a`` and ``b`` (either way), then stop (or after
    10 s without any message).  Every step written out, nothing a daemon could leave out."""
    pin(cpu)
    queues = [open_queue(f"/{link}_{way}_dlnk_phy") for link in (a, b) for way in ("tx", "rx")]
    a_tx, a_rx, b_tx, b_rx = queues
    route = {a_tx.mqd: (a_tx, b_rx, a_rx), b_tx.mqd: (b_tx, a_rx, b_rx)}  # from, to, READY to
    epoll = select.epoll()
    for fd in route:
        epoll.register(fd, select.EPOLLIN)
    up.set()
    relayed = 0
    try:
        while relayed < frames:
            ready = epoll.poll(10.0)
            if not ready:
                break
            for fd, _events in ready:
                source, target, sender = route[fd]
                try:
                    message, _ = source.receive(0)
                except posix_ipc.BusyError:
                    continue
                kind = message[0]
                if kind == 0:  # FRAME: type, 0x55, length (2 bytes, big-endian), payload, CRC-16 (vl2b)
                    end = 4 + int.from_bytes(message[2:4], "big")
                    if binascii.crc_hqx(message[4:end], 0) != int.from_bytes(message[end:end + 2], "big"):
                        continue
                    target.send(message)
                    sender.send(READY_MESSAGE)
                    relayed += 1
                elif kind == 1:  # REQ_STATE
                    sender.send(READY_MESSAGE)
    finally:
        epoll.close()
        for queue in queues:
            queue.close()


def through_relay(count: int, placement: Placement) -> list[float]:
    """As :func:`through_hilgate`, with the bare Python relay (on step 1) instead of the daemon."""
    a, b = f"bra{os.getpid()}", f"brb{os.getpid()}"
    up = mp.Event()
    relay = mp.Process(target=_relay, args=(a, b, 2 * count, placement.cpu(1), up))
    relay.start()
    try:
        up.wait(30)
        return _client(a, b, count, placement)
    finally:
        relay.join(30)
        if relay.is_alive():
            relay.terminate()
            relay.join()
        unlink_queues((a, b))


# -- 2. and 3. through the daemon ------------------------------------------------------------------


SCENE = """\
name: gli-bench
channels: {{ideal: {{speed_mps: 3.0e8}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links:
  {a}: {{vehicle: v, address: 1, bitrate_bps: 1.0e12, fifo_bytes: 10000000, packet: vl2b}}
  {b}: {{vehicle: v, address: 2, bitrate_bps: 1.0e12, fifo_bytes: 10000000, packet: vl2b}}
"""


def _echo(link: str, count: int, mode: str, result, timeout: float = 10.0, cpu: int | None = None,
          said=None) -> None:
    """On link b: echo every frame back to address 1 (``mode`` "echo"), or only count them ("count");
    put (frames received, time of the first, time of the last) on ``result``.  Runs pinned to ``cpu``
    (None: where the kernel puts it); sets the event ``said`` (if any) once it has said REQ_STATE.
    Shared with multihost.py."""
    pin(cpu)
    tx, rx = open_queue(f"/{link}_tx_dlnk_phy"), open_queue(f"/{link}_rx_dlnk_phy")
    tx.send(b"\x01")  # REQ_STATE, as a dccomms application says when it starts: the daemon knows it is there
    if said is not None:
        said.set()
    received = 0
    first = last = 0.0
    while received < count:
        try:
            message, _ = rx.receive(timeout)
        except posix_ipc.BusyError:
            break
        if message[0] != 0:
            continue  # READY/BUSY
        received += 1
        last = time.perf_counter()
        if received == 1:
            first = last
        if mode == "echo":
            tx.send(message[:-4] + (1).to_bytes(4, "little"))
    tx.close()
    rx.close()
    result.put((received, first, last))


def through_hilgate(count: int, placement: Placement) -> list[float]:
    """The client (this thread) on the placement's step 0, the daemon on step 1, the echo on step 2."""
    a, b = f"bga{os.getpid()}", f"bgb{os.getpid()}"
    daemon = Daemon(SCENE.format(a=a, b=b), (a, b), cpu=placement.cpu(1))
    try:
        return _client(a, b, count, placement)
    finally:
        daemon.close()


def round_trip(tx: posix_ipc.MessageQueue, rx: posix_ipc.MessageQueue, message: bytes, timeout: float) -> float:
    """Seconds from putting ``message`` on the application's tx queue to a frame back on its rx queue
    (READY/BUSY on the way are skipped); timed inside, so the call itself is not counted.  Shared with
    multihost.py."""
    start = time.perf_counter()
    tx.send(message)
    while True:
        reply, _ = rx.receive(timeout)
        if reply[0] == 0:
            return time.perf_counter() - start


def _client(a: str, b: str, count: int, placement: Placement) -> list[float]:
    """The round trips of the client on link ``a`` (this thread, on the placement's step 0) against the
    echo on link ``b`` (step 2), through whatever relays the two links (step 1)."""
    result = mp.Queue()
    echo = mp.Process(target=_echo, args=(b, count, "echo", result, 10.0, placement.cpu(2)))
    echo.start()
    tx, rx = open_queue(f"/{a}_tx_dlnk_phy"), open_queue(f"/{a}_rx_dlnk_phy")
    message = frame(b"ping" * 5, 0, 2)
    assert len(message) == MESSAGE
    samples = []
    with pinned(placement.cpu(0)):
        for _ in range(count):
            samples.append(round_trip(tx, rx, message, 5.0))
    echo.join()
    tx.close()
    rx.close()
    return samples[WARM_UP:]


def send_paced(link: str, count: int, size: int, rate: float | None) -> float:
    """As an application on ``link``: send ``count`` frames of ``size``-byte payloads to address 2 at
    ``rate`` a second (sleeping until each is due, in steps of >= 0.5 ms, the sleep's own resolution;
    never spinning: on a 2-core machine a spinning sender takes the daemon's core), or as fast as the
    queue takes them (None), while a thread reads READY/BUSY as a dccomms application's service thread
    does.  Returns when the sending started (``perf_counter``).  Shared with multihost.py."""
    tx, rx = open_queue(f"/{link}_tx_dlnk_phy"), open_queue(f"/{link}_rx_dlnk_phy")
    stop = threading.Event()

    def drain_states() -> None:
        while not stop.is_set():
            try:
                rx.receive(0.1)
            except posix_ipc.BusyError:
                pass

    reader = threading.Thread(target=drain_states, daemon=True)
    reader.start()
    messages = [frame(b"x" * size, i, 2) for i in range(count)]
    start = time.perf_counter()
    try:
        for i, message in enumerate(messages):
            if rate:
                ahead = start + i / rate - time.perf_counter()
                if ahead > 0.0005:
                    time.sleep(ahead)
            tx.send(message)  # blocks when the queue is full, as dccomms' WritePacket does by default
    finally:
        stop.set()
        reader.join()
        tx.close()
        rx.close()
    return start


def throughput(count: int, size: int, rate: float | None) -> tuple[float, int, int]:
    """Frames per second seen by the receiver, frames lost, frames the daemon counted as dropped.
    ``rate`` paces the sender (None: as fast as its queue takes them)."""
    a, b = f"bta{os.getpid()}", f"btb{os.getpid()}"
    daemon = Daemon(SCENE.format(a=a, b=b), (a, b))
    try:
        result, said = mp.Queue(), mp.Event()
        counter = mp.Process(target=_echo, args=(b, count, "count", result), kwargs={"said": said})
        counter.start()
        if not said.wait(60):
            raise RuntimeError("the counter did not start")
        start = send_paced(a, count, size, rate)
        received, first, last = result.get(timeout=120)
        counter.join()
        elapsed = (last - start) or float("nan")
        drops = sum(link["drops"] for link in daemon.status()["links"])
        return received / elapsed, count - received, drops
    finally:
        daemon.close()


def spread(values: list[float]) -> str:
    return " / ".join(f"{v:.0f}" for v in (min(values), statistics.median(values), max(values)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--round-trips", type=int, default=3000)
    parser.add_argument("--frames", type=int, default=20000)
    parser.add_argument("--size", type=int, default=20, help="payload bytes per frame in the throughput test")
    parser.add_argument("--repeats", type=int, default=3, help="alternating bare / relay / hilgate round-trip runs per placement")
    parser.add_argument("--placement", choices=("same", "across", "both"), default="both")
    args = parser.parse_args()
    chosen, why_not = choose(args.placement)
    roles = {"bare": ["ping", "pong"], "hilgate": ["client", "daemon", "echo"]}
    for placement in chosen:
        print(f"{placement.name:>11}: {placement.describe(roles['hilgate'])} (the relay where the daemon is; "
              f"bare: {placement.describe(roles['bare'])})")
    if why_not:
        print(why_not)
    sides = [("bare", bare), ("relay", through_relay), ("hilgate", through_hilgate)]
    # (placement, side) -> [(p50, p99) per repeat]
    measured: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for repeat in range(1, args.repeats + 1):
        for k in range(len(chosen)):
            placement = chosen[(repeat - 1 + k) % len(chosen)]  # each placement goes first in turn
            turn = (repeat - 1) % len(sides)
            order = sides[turn:] + sides[:turn]  # and, from one repeat to the next, each side
            load = os.getloadavg()[0]
            got = {}
            for side, run in order:
                got[side] = percentiles(run(args.round_trips + WARM_UP, placement))
                measured.setdefault((placement.name, side), []).append(got[side])
            (bare_p50, bare_p99), (rel_p50, rel_p99), (hil_p50, hil_p99) = got["bare"], got["relay"], got["hilgate"]
            print(f"repeat {repeat}, {placement.name:>11}: bare POSIX-queue ping-pong (2 hops) p50 {bare_p50 * 1e6:.0f} µs "
                  f"(p99 {bare_p99 * 1e6:.0f}); bare Python relay (4 hops) p50 {rel_p50 * 1e6:.0f} µs (p99 {rel_p99 * 1e6:.0f}), "
                  f"added p50 {(rel_p50 - bare_p50) * 1e6:.0f} µs; "
                  f"through hilgate (4 hops) p50 {hil_p50 * 1e6:.0f} µs (p99 {hil_p99 * 1e6:.0f}); "
                  f"added p50 {(hil_p50 - bare_p50) * 1e6:.0f} µs (p99 {(hil_p99 - bare_p99) * 1e6:.0f}); "
                  f"first: {order[0][0]}; load average {load:.2f}", flush=True)
    print(f"round trip of a {MESSAGE}-byte message, {args.round_trips:,} round trips x {args.repeats} per placement, "
          f"min / median / max over the repeats, µs:")
    for placement in chosen:
        bares, rels, hils = (measured[(placement.name, side)] for side in ("bare", "relay", "hilgate"))
        relay50 = [1e6 * (r[0] - b[0]) for r, b in zip(rels, bares)]
        added50 = [1e6 * (h[0] - b[0]) for h, b in zip(hils, bares)]
        added99 = [1e6 * (h[1] - b[1]) for h, b in zip(hils, bares)]
        beyond = [1e6 * (h[0] - r[0]) for h, r in zip(hils, rels)]
        print(f"  {placement.name:>11}: bare p50 {spread([1e6 * b[0] for b in bares])}, relay p50 "
              f"{spread([1e6 * r[0] for r in rels])}, hilgate p50 {spread([1e6 * h[0] for h in hils])}; "
              f"added by the bare Python relay p50 {spread(relay50)}; added by hilgate p50 {spread(added50)}, "
              f"p99 {spread(added99)}; hilgate beyond the relay p50 {spread(beyond)}", flush=True)
    print("(target: <= 40 µs added at p50, pinned)")
    if args.frames <= 0:
        return  # (--frames 0: the round trips alone)
    print("throughput: unpinned (the kernel places the sender, the daemon and the counter)")
    for offered in (5000, 10000, 20000, None):
        rate, lost, drops = throughput(args.frames, args.size, offered)
        label = f"{offered:,}/s offered" if offered else "flat out"
        print(f"throughput through one link, {args.size}-byte payloads, {label:>16}: {rate:,.0f} frames/s received, "
              f"{lost} lost, {drops} dropped by the daemon", flush=True)
    print("(target: zero loss up to 20,000 frames/s)")


if __name__ == "__main__":
    main()
