"""The daemon end to end: separate application processes, real POSIX queues and sockets.

Timing assertions use the model's own arithmetic (exact, from the trace) and, for what the
applications see on the wall clock, only what holds on any host however loaded: never earlier than
the model minus 2 ms (the frame cannot arrive before it was sent plus its delay).  How late it may
be is a benchmark's question (benchmarks/realtime_lateness.py), not a test's.
"""

import binascii
import json
import os
import posix_ipc
import socket
import subprocess
import sys
import time

import pytest

from daemon_kit import SCENE_HEAD, Daemon, free_port, peer_events, two_links, unique
from hilgate.gli import wire
from hilgate.client import GliError, Link

# a and b are 150 m apart on a 1500 m/s channel (tau = 0.1 s), 1000 bit/s, tx delay 0.05 s:
# a 10-byte payload is a 15-byte VariableLength2BPacket on air (T = 0.12 s), so 0.27 s end to end.
EXPECTED = 0.05 + 0.12 + 0.1


def scene(a: str, b: str, *, bitrate: float = 1000, tx_delay: float = 0.05, extra: str = "") -> str:
    return f"""\
name: daemon-test
{SCENE_HEAD}links:
  {a}: {{vehicle: va, address: 1, bitrate_bps: {bitrate}, tx_delay_s: {tx_delay}, packet: vl2b}}
  {b}: {{vehicle: vb, address: 2, bitrate_bps: 1000, tx_delay_s: 0.05, packet: vl2b}}
{extra}"""


@pytest.fixture
def pair(daemon_of):
    return two_links(daemon_of, scene)


def test_ready_only_once_every_endpoint_is_up(pair):
    daemon, a, b = pair
    # READY=1 has been received: every queue, socket and the control socket must exist already
    for link in (a, b):
        for direction in ("tx", "rx"):
            posix_ipc.MessageQueue(f"/{link}_{direction}_dlnk_phy").close()  # no O_CREAT: must exist
        assert os.path.exists(os.path.join(daemon.runtime, "gli", f"{link}.sock"))
    assert os.path.exists(os.path.join(daemon.runtime, "control.sock"))
    ready = next(n for n in daemon.notifications if "READY=1" in n.split("\n"))
    assert any(line.startswith("STATUS=") for line in ready.split("\n"))
    assert any(line == f"MAINPID={daemon.process.pid}" for line in ready.split("\n"))


def test_dccomms_peers_exchange_frames_through_the_queues(pair, busy_host):
    daemon, a, b = pair
    receiver = daemon.peer(b, "--receive", "5", "--timeout", "60")
    time.sleep(0.3)
    sender = daemon.peer(a, "--send", "5", "--dst", "2", "--interval", "0.4", "--receive", "0", "--timeout", "3")
    sent = [e for e in peer_events(sender) if e["ev"] == "sent"]
    received = [e for e in peer_events(receiver) if e["ev"] == "frame"]
    assert [e["payload"] for e in received] == [e["payload"] for e in sent]
    for s, r in zip(sent, received):
        assert r["crc_ok"] and r["body_len"] == 2065
        assert (r["seq"], r["src"], r["dst"]) == (s["seq"], 1, 2)
        seen = r["mono"] - s["mono"]
        assert EXPECTED - 0.002 <= seen, seen
    # the model's arithmetic in real time is exact
    events = daemon.trace_events()
    for pkt in {e["pkt"] for e in events if e.get("ev") == "rx"}:
        enq = next(e["t"] for e in events if e.get("pkt") == pkt and e["ev"] == "enq")
        rx = next(e["t"] for e in events if e.get("pkt") == pkt and e["ev"] == "rx")
        assert rx - enq == pytest.approx(EXPECTED, abs=1e-6)


def test_ready_busy_and_req_state_as_dccomms_does(pair):
    daemon, a, b = pair
    sender = daemon.peer(a, "--send", "1", "--dst", "2", "--receive", "50", "--timeout", "1.5")
    states = [e["ready"] for e in peer_events(sender) if e["ev"] == "state"]
    # the start-up BUSY then READY, the answer to REQ_STATE, then READY once the frame is sent: no BUSY for
    # it, since dccomms' WritePacket has already made the application BUSY in its own eyes
    assert states[:2] == [False, True]
    assert states[-1] is True and False not in states[2:]


def test_a_frame_that_leaves_at_once_still_gets_its_ready(daemon_of):
    """dccomms' ``WritePacket`` marks the PHY BUSY in the application itself, and
    ``WaitForDeviceReadyToTransmit`` (hello_world_tx calls it before every frame) waits for a READY
    from the device.  So every frame an application writes must be answered by a READY once the link
    is free again, even when the frame is on air and gone within the same pass of the loop (a fast
    link, a short frame) and the link's own state never looked BUSY from outside."""
    a, b = unique("a"), unique("b")
    daemon = daemon_of(scene(a, b, bitrate=1e12, tx_delay=0.0), [a, b])
    tx = rx = None
    try:
        tx = posix_ipc.MessageQueue(f"/{a}_tx_dlnk_phy")
        rx = posix_ipc.MessageQueue(f"/{a}_rx_dlnk_phy")

        def next_state(timeout: float = 10.0) -> int | None:
            deadline = time.monotonic() + timeout
            while (left := deadline - time.monotonic()) > 0:
                try:
                    message, _ = rx.receive(left)
                except posix_ipc.BusyError:
                    return None
                if message[0] == 2:  # CMD_STATE
                    return message[1]
            return None

        tx.send(b"\x01")  # REQ_STATE, as a dccomms application's Start does
        while next_state() != 1:
            pass
        payload = b"hello"
        real = b"\x55" + len(payload).to_bytes(2, "big") + payload + binascii.crc_hqx(payload, 0).to_bytes(2, "big")
        body = real.ljust(2053, b"\0") + (0).to_bytes(4, "little") + (1).to_bytes(4, "little") + (2).to_bytes(4, "little")
        for _ in range(3):
            tx.send(b"\x00" + body)  # the application is BUSY now, in its own eyes
            states = []
            while (state := next_state()) is not None and state != 1:
                states.append(state)
            assert state == 1, f"no READY after the frame (states seen: {states})"
        garbage = b"\x00" + b"\x13" * 2065  # refused (no preamble): the application still waits for READY
        tx.send(garbage)
        assert next_state() == 1
    finally:
        for queue in (tx, rx):
            if queue is not None:
                queue.close()


def test_socket_clients_over_unix_and_tcp(daemon_of, busy_host):
    a, b = unique("a"), unique("b")
    port = free_port()
    daemon = daemon_of(scene(a, b), [a, b], "--tcp", str(port))
    with Link.open(a, runtime_dir=daemon.runtime) as la, \
            Link.open(b, tcp=("127.0.0.1", port), runtime_dir=daemon.runtime) as lb:  # its RUNTIME/tcp.token
        assert (la.address, lb.address) == (1, 2)
        assert la.info["packet"] == "vl2b" and la.max_payload == 2048
        sent_at = time.monotonic()
        la.send(b"over unix", dst=2)
        message = lb.recv(timeout=30)
        seen = time.monotonic() - sent_at
        assert (message.src, message.dst, message.data) == (1, 2, b"over unix")
        expected = 0.05 + 14 * 8 / 1000 + 0.1  # a 9-byte payload is 14 bytes on air
        assert expected - 0.002 <= seen
        lb.send(b"broadcast back")
        message = la.recv(timeout=30)
        assert (message.src, message.dst, message.data) == (2, 255, b"broadcast back")
        assert la.recv(timeout=0.3) is None
        with pytest.raises(GliError, match="do not fit"):
            la.send(b"x" * 3000, dst=2)
            la.recv(timeout=30)
    with pytest.raises(GliError, match="no link"):
        Link.open("nosuchlink", tcp=("127.0.0.1", port), token_file=os.path.join(daemon.runtime, "tcp.token"))


def test_bad_frames_are_counted_traced_and_dropped(pair):
    daemon, a, b = pair
    bad_crc = "00" + ("55" + "0002" + "6869" + "0000").ljust(2053 * 2, "0") + "00" * 12
    wrong_size = "00" + "55" * 100
    unknown_type = "07" + "00" * 4
    empty = ""
    sender = daemon.peer(a, "--send", "0", "--raw", ",".join([bad_crc, wrong_size, unknown_type]))
    peer_events(sender)
    queue = posix_ipc.MessageQueue(f"/{a}_tx_dlnk_phy")
    queue.send(empty)
    queue.close()
    receiver = daemon.peer(b, "--receive", "1", "--timeout", "60")
    time.sleep(0.3)
    after = daemon.peer(a, "--send", "1", "--dst", "2", "--timeout", "1")
    peer_events(after)
    assert [e["payload"] for e in peer_events(receiver) if e["ev"] == "frame"] == [f"{a}#0000".ljust(10, ".")[:10]]
    assert daemon.link_status(a)["drops"] == 4
    causes = sorted(e["cause"] for e in daemon.trace_events() if e["ev"] == "drop" and e.get("src") == "app")
    assert causes == ["crc", "size", "size", "type"]
    assert daemon.process.poll() is None


def test_a_client_that_vanishes_mid_frame_or_speaks_garbage_changes_nothing(pair):
    daemon, a, b = pair
    path = os.path.join(daemon.runtime, "gli", f"{a}.sock")
    for junk in (wire.encode_send(2, b"complete frame")[:7], b"\xff\xff\xff\xff\x03garbage", b"\x00"):
        with socket.socket(socket.AF_UNIX) as raw:
            raw.connect(path)
            raw.sendall(junk)
    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        la.send(b"still fine", dst=2)
        assert lb.recv(timeout=30).data == b"still fine"
    assert daemon.status()["links"][0]["state"] == "up"


def test_a_slow_application_loses_nothing_within_the_backlog_and_the_rest_is_counted(daemon_of):
    a, b = unique("a"), unique("b")
    daemon = daemon_of(scene(a, b, bitrate=1e6, tx_delay=0.0), [a, b], "--gli-backlog", "5")
    quiet = daemon.peer(b, "--receive", "0", "--timeout", "0")  # opens b's queues, then reads nothing
    peer_events(quiet)
    with Link.open(a, runtime_dir=daemon.runtime) as la:
        for i in range(30):
            la.send(b"%02d" % i, dst=2)
        deadline = time.monotonic() + 60
        while daemon.link_status(b)["rx_packets"] < 30 and time.monotonic() < deadline:
            time.sleep(0.1)
    # b's queue holds 10 messages: BUSY and READY from start-up, READY answering the peer's REQ_STATE,
    # then 7 frames; 5 more wait in the backlog; the other 18 are dropped and counted
    assert daemon.link_status(b)["drops"] == 18
    # now b's application wakes up and reads: it gets the 12 frames in order, none twice (the 5 of the
    # backlog come once the daemon sees room in the queue: waited for, however long a loaded host takes)
    reader = daemon.peer(b, "--receive", "12", "--timeout", "60")
    frames = [e for e in peer_events(reader, 90) if e["ev"] == "frame"]
    assert [f["payload"] for f in frames] == ["%02d" % i for i in range(12)]
    more = daemon.peer(b, "--receive", "1", "--timeout", "1")
    assert not [e for e in peer_events(more) if e["ev"] == "frame"]
    assert daemon.process.poll() is None
    daemon.stop()
    causes = [e.get("cause") for e in daemon.trace_events() if e.get("ev") == "drop"]
    assert causes.count("app_full") == 18 and "no_reader" not in causes  # each loss counted once, as its own


def test_sighup_swaps_a_link_while_an_application_keeps_sending(pair):
    daemon, a, b = pair
    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        def exchange(tag: bytes) -> None:
            la.send(tag, dst=2)
            assert lb.recv(timeout=30).data == tag

        exchange(b"before")  # 6 bytes: 11 on air, 0.05 + 0.088 + 0.1 s
        # 10x slower modem and no intrinsic delay: 11 bytes at 100 bit/s = 0.88 s, + 0.1 s
        daemon.reload(scene(a, b, bitrate=100, tx_delay=0.0))
        exchange(b"after!")
        assert la.info and lb.info  # the same connections, never re-opened
        assert daemon.status()["links"][0]["tx_packets"] == 2  # statistics survive the swap
    daemon.stop()  # the trace is complete once the daemon has stopped
    events = daemon.trace_events()
    delays = {}
    for e in events:
        if e.get("ev") == "enq":
            delays[e["pkt"]] = -e["t"]
        elif e.get("ev") == "rx":
            delays[e["pkt"]] += e["t"]
    assert sorted(round(d, 6) for d in delays.values()) == [0.238, 0.98]


def test_an_invalid_reload_is_refused_and_the_old_scene_keeps_running(pair):
    daemon, a, b = pair
    daemon.scene.write_text(scene(a, b).replace("bitrate_bps: 1000,", "bitrate_bsp: 1000,", 1))
    reply = daemon.control({"class": "RELOAD"})
    assert reply["ok"] is False and "bitrate_bsp" in reply["error"] and "did you mean" in reply["error"]
    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        la.send(b"old scene", dst=2)
        assert lb.recv(timeout=30).data == b"old scene"
    assert "reload refused" in daemon.output()


def test_status_command_prints_the_documented_json(pair):
    daemon, a, b = pair
    result = subprocess.run([sys.executable, "-m", "hilgate", "status", "--json", "--runtime-dir", daemon.runtime],
                            capture_output=True, text=True, timeout=20)
    assert result.returncode == 0, result.stderr
    status = json.loads(result.stdout)
    assert list(status) == ["links", "vehicles", "scheduling"]
    assert [list(link) for link in status["links"]] == [
        ["id", "backend", "state", "tx_packets", "rx_packets", "drops", "fifo_bytes", "unread", "drop_causes",
         "clients", "ready", "app_dst", "since_s", "since"]] * 2
    assert all(link["since_s"] == 0.0 and link["since"].endswith("+00:00") for link in status["links"])
    assert all(link["ready"] is True for link in status["links"])  # idle links
    assert status["vehicles"][1] == {"name": "vb", "source": "static", "position": [150.0, 0.0, 0.0], "age_s": 0.0,
                                     "stale": None, "heading": None}
    assert list(status["scheduling"]) == ["kind", "policy", "priority", "nice", "memory_locked", "asked_priority",
                                          "notes", "text"]
    table = subprocess.run([sys.executable, "-m", "hilgate", "status", "--runtime-dir", daemon.runtime],
                           capture_output=True, text=True, timeout=20)
    assert a in table.stdout and "vehicle" in table.stdout


def test_send_and_listen_tools(pair):
    daemon, a, b = pair
    listener = subprocess.Popen([sys.executable, "-m", "hilgate", "listen", b, "--count", "2", "--timeout", "60",
                                 "--runtime-dir", daemon.runtime], stdout=subprocess.PIPE, text=True)
    daemon.wait_clients(b)  # it hears only what is sent once it is attached, and its start-up alone takes about
    # a second on a loaded host: a fixed 1 s sleep here lost "first line" whenever it was slower
    subprocess.run([sys.executable, "-m", "hilgate", "send", a, "--to", "2", "--runtime-dir", daemon.runtime],
                   input="first line\nsecond line\n", text=True, check=True, timeout=60)
    out, _ = listener.communicate(timeout=90)
    assert [line.split(": ", 1)[1] for line in out.splitlines()] == ["first line", "second line"]
    assert all(" 1 -> 2: " in line for line in out.splitlines())


def test_sigterm_leaves_a_complete_trace_and_summary(pair):
    daemon, a, b = pair
    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        for i in range(3):
            la.send(b"m%d" % i, dst=2)
        for _ in range(3):
            lb.recv(timeout=30)
    assert daemon.stop() == 0
    lines = daemon.trace.read_text().splitlines()
    events = [json.loads(line) for line in lines]  # every line is complete JSON
    assert [e["ev"] for e in events].count("rx") == 3
    summary = json.loads(daemon.summary.read_text())
    assert [l["tx_packets"] for l in summary["links"]] == [3, 0]
    assert "STOPPING=1" in daemon.notifications[-1].split("\n") or daemon.wait_for("STOPPING=1", 5)


def test_speed_paces_the_model(daemon_of):
    a, b = unique("a"), unique("b")
    daemon = daemon_of(scene(a, b, bitrate=100, tx_delay=0.0), [a, b], "--speed", "4")
    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        start = time.monotonic()
        la.send(b"fast forward", dst=2)  # 17 B at 100 bit/s + 0.1 s = 1.46 model s
        message = lb.recv(timeout=30)
        seen = time.monotonic() - start
        # the model clock runs 4 times the wall clock: two STATUS stamps t1, t2 lie inside the
        # outer wall interval and outside the inner one, whatever the load
        outer_start = time.monotonic()
        t1 = daemon.status()["time"]
        inner_start = time.monotonic()
        time.sleep(0.5)
        inner = time.monotonic() - inner_start
        t2 = daemon.status()["time"]
        outer = time.monotonic() - outer_start
    assert message.data == b"fast forward"
    assert 1.46 / 4 - 0.002 <= seen
    assert 4 * inner - 0.001 <= t2 - t1 <= 4 * outer + 0.001


def test_a_bad_scene_does_not_start(tmp_path):
    a, b = unique("a"), unique("b")
    daemon = Daemon(tmp_path, scene(a, b).replace("speed_mps: 1500", "speed_mps: sound"), [a, b])
    try:
        assert daemon.process.wait(20) == 2
        assert "channels.ac.speed_mps: must be a number" in daemon.output()
        with pytest.raises(posix_ipc.ExistentialError):
            posix_ipc.MessageQueue(f"/{a}_tx_dlnk_phy")
    finally:
        daemon.close()
