"""Several daemons, one network: three hosts on this machine, joined over Zenoh on loopback TCP.

Host A carries simulated vehicles and an application on its socket GLI; host B an emulated EvoLogics
modem on a pty, driven by an AT client of this test (its own framing, not hilgate's codec); host C
only a socket-GLI application.  Each daemon has its own runtime directory, free loopback ports and
a Zenoh key prefix of its own test run, so other runs on the machine never meet it.  Model times
are compared across hosts through the epochs each daemon writes in its trace (``network`` line).
The daemons join with credentials made by ``hilgate network init`` for this module (TLS, access
control); the attacks on them are in tests/test_netauth.py.
"""

from __future__ import annotations

import json
import math
import re
import signal
import socket
import subprocess
import sys
import time
import uuid

import pytest
import serial

from daemon_kit import Daemon, free_port, unique, wait_until  # noqa: E402
from hilgate.client import Link  # noqa: E402
from hilgate.core.packets import packet_class  # noqa: E402
from test_live_poses import FakeBlueRov  # noqa: E402  (pymavlink's ArduSub, as in the one-host test)

VL2B = packet_class("vl2b")


CREDS = ""  # the lab's credentials for this module's daemons (hosts A-D and solo, applications app-1, app-2)


@pytest.fixture(scope="module", autouse=True)
def credentials(tmp_path_factory):
    from hilgate.netinit import init_network

    global CREDS
    CREDS = str(tmp_path_factory.mktemp("creds"))
    init_network(CREDS, ["A", "B", "C", "D", "solo"], 2)
    return CREDS




class Host:
    """One daemon of the network, in its own directory."""

    def __init__(self, tmp_path, name: str, scene: str, links: list[str], listen: int, connect: list[int] = (),
                 extra: tuple[str, ...] = (), scheme: str = "tls"):
        self.name = name
        self.dir = tmp_path / name
        self.dir.mkdir(parents=True, exist_ok=True)
        self.listen = listen
        args = ["--host", name, "--zenoh-listen", f"{scheme}/127.0.0.1:{listen}",
                *(arg for port in connect for arg in ("--zenoh-connect", f"{scheme}/127.0.0.1:{port}")), *extra]
        self.daemon = Daemon(self.dir, scene, links, *args)

    def status(self) -> dict:
        return self.daemon.status()

    def sees(self, *hosts: str) -> bool:
        views = {v["host"]: v["state"] for v in self.status()["network"]["hosts"]}
        return all(views.get(h) == "up" for h in hosts)

    def remote_link(self, link: str) -> str:
        return next(l["state"] for l in self.status()["network"]["remote_links"] if l["id"] == link)

    def events(self) -> list[dict]:
        return self.daemon.trace_events()

    def epoch_ns(self) -> int:
        runs = [e for e in self.events() if e.get("ev") == "network"]
        return runs[-1]["epoch_ns"]


def to_host(t: float, source: Host, target: Host) -> float:
    """A model time of ``source`` in ``target``'s model time (the daemons' own arithmetic)."""
    return t + (source.epoch_ns() - target.epoch_ns()) * 1e-9


class AtClient:
    """An EvoLogics host of our own: writes AT commands, reads RECVIMs by their length field."""

    def __init__(self, path):
        self.port = serial.Serial(str(path), 19200, timeout=0.2)
        self.buffer = b""

    def command(self, text: str) -> None:
        self.port.write(text.encode() + b"\r\n")

    def send_im(self, dst: int, data: bytes, ack: bool = False) -> None:
        kind = b"ack" if ack else b"noack"
        self.port.write(b"AT*SENDIM,%d,%d,%s," % (len(data), dst, kind) + data + b"\r\n")

    def wait_line(self, prefix: bytes, timeout: float = 60.0) -> bytes | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in self.buffer.split(b"\r\n")[:-1]:
                if line.startswith(prefix):
                    return line
            self.buffer += self.port.read(4096)
        return None

    def recvim(self, timeout: float = 60.0) -> tuple[int, bytes] | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            match = re.search(rb"RECVIM,(\d+),(\d+),(\d+),(no)?ack,(-?\d+),(-?\d+),(\d+),(-?[\d.]+),", self.buffer)
            if match:
                length = int(match.group(1))
                end = match.end() + length
                if len(self.buffer) >= end:
                    data = self.buffer[match.end():end]
                    self.buffer = self.buffer[end:]
                    return int(match.group(2)), data
            self.buffer += self.port.read(4096)
        return None

    def close(self) -> None:
        self.port.close()


SLOW_SOUND_MPS = 375.0
"""The three-host scene's sound speed: a quarter of water's, so that every hop's flight (0.4–0.9 s) leaves
a busy host's scheduling and Zenoh's delivery far more time than they take, and no arrival is late.
The lease is long for the same reason (a starved Zenoh thread misses keep-alives; at 0.5 s, hosts were
seen down under load): a killed host is seen down at once anyway, when its connections close."""


def network_scene(prefix: str, a: str, b: str, c: str, pty) -> str:
    return f"""\
channels: {{ac: {{speed_mps: {SLOW_SOUND_MPS}}}}}
zenoh: {{prefix: {prefix}, lease_s: 5, credentials: {CREDS}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {{static: [150, 0, 0]}}}}
  vc: {{pose: {{static: [0, 300, 0]}}}}
# strict: a frame goes to the modem it names, so each hop is checked on its own.  A maximum range
# gives an acknowledged IM the wait a real modem has (a round trip at 1 km), not the exact round trip
# to its addressee plus 1 ms, which a busy host's scheduling alone can exceed.
links:
  {a}: {{vehicle: va, host: A, address: 1, bitrate_bps: 1000, addressing: strict, range_m: [0, 1000]}}
  {b}: {{vehicle: vb, host: B, address: 2, bitrate_bps: 1000, addressing: strict, range_m: [0, 1000],
        emulate: {{protocol: evologics, pty: {pty}}}}}
  {c}: {{vehicle: vc, host: C, address: 3, bitrate_bps: 1000, addressing: strict, range_m: [0, 1000]}}
"""


def two_hosts_scene(zenoh: str, a: str, b: str, speed_mps: float, bitrate_bps: float) -> str:
    """Link ``a`` (address 1) on host A and ``b`` (address 2) on host B, 150 m apart, strictly addressed;
    ``zenoh`` is what the scene's ``zenoh`` section holds."""
    return f"""\
channels: {{ac: {{speed_mps: {speed_mps}}}}}
zenoh: {{{zenoh}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {{static: [150, 0, 0]}}}}
links:
  {a}: {{vehicle: va, host: A, address: 1, bitrate_bps: {bitrate_bps}, addressing: strict}}
  {b}: {{vehicle: vb, host: B, address: 2, bitrate_bps: {bitrate_bps}, addressing: strict}}
"""


def airtime(payload: int) -> float:
    return (1 + 2 + payload + 2) * 8 / 1000  # vl2b: preamble, length, payload, CRC at 1000 b/s


@pytest.fixture
def network(tmp_path):
    prefix = f"hilgate-test-{uuid.uuid4().hex[:8]}"
    a, b, c = unique("na"), unique("nb"), unique("nc")
    pty = tmp_path / "ttyEVO"
    scene = network_scene(prefix, a, b, c, pty)
    ports = [free_port() for _ in range(3)]
    hosts = {"A": Host(tmp_path, "A", scene, [a], ports[0])}
    hosts["A"].daemon.wait_for("READY=1")
    hosts["B"] = Host(tmp_path, "B", scene, [b], ports[1], [ports[0]])
    hosts["C"] = Host(tmp_path, "C", scene, [c], ports[2], [ports[0]])
    try:
        for name in "BC":
            hosts[name].daemon.wait_for("READY=1")
        for name, host in hosts.items():
            wait_until(lambda: host.sees(*(h for h in hosts if h != name)), what=f"{name} to see the others")
        yield {"hosts": hosts, "links": (a, b, c), "pty": pty, "prefix": prefix, "scene": scene, "ports": ports,
               "tmp": tmp_path}
    finally:
        for host in hosts.values():
            host.daemon.close()


def test_three_hosts_share_one_channel_with_exact_model_times(network, busy_host):
    A, B, C = (network["hosts"][h] for h in "ABC")
    a, b, c = network["links"]
    at = AtClient(network["pty"])
    try:
        with Link.open(a, runtime_dir=A.daemon.runtime) as la, Link.open(c, runtime_dir=C.daemon.runtime) as lc:
            start = time.monotonic()
            la.send(b"A to B", dst=2)                        # A -> B: the emulated modem prints a RECVIM
            received = at.recvim()
            seen = time.monotonic() - start
            assert received == (1, b"U\x00\x06A to B" + received[1][-2:])  # the whole vl2b packet, as on air
            assert seen >= airtime(6) + 150 / SLOW_SOUND_MPS - 0.002  # never before the model's time (150 m)
            at.send_im(1, VL2B.encode(b"B to A"))             # B -> A, from the AT client (a vl2b frame, as on air:
            #                                                   a simulated link's application gets what a bridge makes of it)
            message = la.recv(timeout=30)
            assert (message.src, message.data) == (2, b"B to A")
            lc.send(b"C to A", dst=1)                         # C -> A (300 m)
            message = la.recv(timeout=30)
            assert (message.src, message.data) == (3, b"C to A")
            la.send(b"everyone", dst=255)                     # a broadcast reaches every host
            assert at.recvim()[1][3:-2] == b"everyone"
            message = lc.recv(timeout=30)
            assert (message.src, message.data) == (1, b"everyone")
            assert la.recv(timeout=0.5) is None and lc.recv(timeout=0.2) is None  # nothing else, no echo
            at.send_im(1, VL2B.encode(b"ack me"), ack=True)   # the acoustic ACK comes back from host A
            assert la.recv(timeout=30).data == b"ack me"
            assert at.wait_line(b"DELIVEREDIM") == b"DELIVEREDIM,1", at.buffer[-400:]
        # every host shows every vehicle; status --network lists each host's links
        for host in (A, B, C):
            assert {v["name"] for v in host.status()["vehicles"]} == {"va", "vb", "vc"}
        answer = subprocess.run([sys.executable, "-m", "hilgate", "status", "--network", "--json", "--runtime-dir",
                                 B.daemon.runtime], capture_output=True, text=True, timeout=30)
        assert answer.returncode == 0, answer.stderr
        hosts = {h["host"]: h for h in json.loads(answer.stdout)}
        assert set(hosts) == {"A", "B", "C"}
        assert {h: [l["id"] for l in v["links"]] for h, v in hosts.items()} == {"A": [a], "B": [b], "C": [c]}
        assert {v["host"]: v["state"] for v in hosts["A"]["hosts"]} == {"B": "up", "C": "up"}
    finally:
        at.close()
    for host in (A, B, C):
        host.daemon.stop()
    # model times: the arrival on the receiving host is the sender's start + τ + air time, exactly; or,
    # when a busy machine made the transmission heard after that (rare, even so slow a sound), the arrival
    # is when it was heard and its lateness is traced, exactly
    ev = {name: host.events() for name, host in (("A", A), ("B", B), ("C", C))}
    late = {(e["link"], e["src"], e["pkt"]): e["lateness_s"] for events in ev.values() for e in events
            if e.get("ev") == "late"}
    sent = {name: {e["pkt"]: e["t"] for e in events if e.get("ev") == "tx"} for name, events in ev.items()}
    hosts = {"A": A, "B": B, "C": C}
    by_link = {a: "A", b: "B", c: "C"}
    checked = 0
    distance = {frozenset("AB"): 150.0, frozenset("AC"): 300.0, frozenset("BC"): math.hypot(150, 300)}
    for receiver, events in ev.items():
        for e in (e for e in events if e.get("ev") == "rx"):
            sender = by_link[e["src"]]
            t_tx = to_host(sent[sender][e["pkt"]], hosts[sender], hosts[receiver])
            expected = t_tx + distance[frozenset(sender + receiver)] / SLOW_SOUND_MPS + e["size"] * 8 / 1000
            expected += late.get((e["link"], e["src"], e["pkt"]), 0.0)
            assert e["t"] == pytest.approx(expected, abs=1e-6), (receiver, e)
            checked += 1
    assert checked == 7  # A->B, B->A, C->A, the broadcast at B and C, B's acknowledged IM and A's ACK
    assert not [e for events in ev.values() for e in events if e.get("ev") == "err"]


def test_a_host_that_dies_is_down_on_the_others_and_rejoins_without_restarting_them(network):
    A, B, C = (network["hosts"][h] for h in "ABC")
    a, b, c = network["links"]
    assert A.remote_link(b) == "up"
    B.daemon.process.send_signal(signal.SIGKILL)
    B.daemon.process.wait()
    wait_until(lambda: A.remote_link(b) == "down", what="B's link to go down on A")
    assert not A.sees("B") and A.sees("C")
    with Link.open(a, runtime_dir=A.daemon.runtime) as la, Link.open(c, runtime_dir=C.daemon.runtime) as lc:
        la.send(b"to nobody", dst=2)
        wait_until(lambda: A.daemon.link_status(a)["drop_causes"].get("host_down") == 1, what="host_down")
        lc.send(b"the others go on", dst=1)
        assert la.recv(timeout=30).data == b"the others go on"
        # B comes back (same name, same port): A and C go on without a restart
        B.daemon.close()
        B2 = Host(network["tmp"] / "again", "B", network["scene"], [b], network["ports"][1], [network["ports"][0]])
        network["hosts"]["B"] = B2
        B2.daemon.wait_for("READY=1")
        wait_until(lambda: A.remote_link(b) == "up", what="B's link to come back on A")
        at = AtClient(network["pty"])
        try:
            la.send(b"welcome back", dst=2)
            assert at.recvim()[1][3:-2] == b"welcome back"
        finally:
            at.close()
    A.daemon.stop()
    errors = [e for e in A.events() if e.get("ev") == "err"]
    assert [(e["cause"], e["dst"]) for e in errors] == [("host_down", b)]
    states = [e["state"] for e in A.events() if e.get("ev") == "host" and e["host"] == "B"]
    assert states[-2:] == ["down", "up"]
    # the restarted B numbers its messages from 1 again: a new session, not a gap (nor a replay)
    assert not [e for e in A.events() if e.get("cause") in ("net_gap", "replay")]


def test_an_application_reaches_a_link_over_zenoh_from_anywhere(network, busy_host):
    a = network["links"][0]
    at = AtClient(network["pty"])
    try:
        endpoint = f"tls/127.0.0.1:{network['ports'][2]}"  # through C's daemon, for a link A serves
        with Link.open(a, zenoh={"connect": [endpoint], "prefix": network["prefix"],
                                 "credentials": f"{CREDS}/apps/app-1"}) as link:
            assert link.address == 1 and link.max_payload > 0
            assert link.command({"class": "POSE"})["position"] == [0.0, 0.0, 0.0]
            link.send(b"over zenoh", dst=2)
            assert at.recvim()[1][3:-2] == b"over zenoh"
            at.send_im(1, VL2B.encode(b"and back"))
            message = link.recv(timeout=30)
            assert (message.src, message.data) == (2, b"and back")
            with pytest.raises(Exception, match="do not fit"):
                link.send(b"x" * 5000, dst=2)
                time.sleep(1.0)
                link.recv(timeout=30)
    finally:
        at.close()


def test_the_same_host_name_or_link_twice_is_refused(network, tmp_path):
    a = network["links"][0]
    port = free_port()
    twin = Host(tmp_path / "twin", "A", network["scene"], [], port, [network["ports"][0]])
    assert twin.daemon.process.wait(30) == 1  # refused, as a link held by another daemon on this host is
    assert "host name 'A' is already used" in twin.daemon.output()
    other = network["scene"].replace(f"{a}: {{vehicle: va, host: A,", f"{a}: {{vehicle: va, host: D,")
    thief = Host(tmp_path, "D", other, [], free_port(), [network["ports"][0]])
    assert thief.daemon.process.wait(30) == 1
    assert f"link {a} is already served by another daemon" in thief.daemon.output()
    assert network["hosts"]["A"].daemon.process.poll() is None


def test_a_pose_measured_on_one_host_moves_the_delays_on_another_exactly(tmp_path):
    prefix = f"hilgate-test-{uuid.uuid4().hex[:8]}"
    top, rov = unique("top"), unique("rov")
    mav_port = free_udp = free_port(socket.SOCK_DGRAM)
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
zenoh: {{prefix: {prefix}, credentials: {CREDS}}}
vehicles:
  topside: {{pose: {{static: [0, 0, 0]}}, host: A}}
  bluerov:
    pose: {{mavlink: {{url: "udpin:127.0.0.1:{free_udp}", system_id: 1}}}}
    host: B
links:
  {top}: {{vehicle: topside, host: A, address: 1, bitrate_bps: 1000, addressing: strict}}
  {rov}: {{vehicle: bluerov, host: A, address: 2, bitrate_bps: 1000, addressing: strict}}
"""
    pa = free_port()
    A = Host(tmp_path, "A", scene, [top, rov], pa)
    B = Host(tmp_path, "B", scene, [], free_port(), [pa])
    vehicle = FakeBlueRov(mav_port)
    try:
        A.daemon.wait_for("READY=1")
        B.daemon.wait_for("READY=1")

        def position_on_a():
            return next(v for v in A.status()["vehicles"] if v["name"] == "bluerov")["position"]

        wait_until(lambda: position_on_a() == [150.0, 0.0, 5.0], what="B's MAVLink pose on A")
        with Link.open(top, runtime_dir=A.daemon.runtime) as lt, Link.open(rov, runtime_dir=A.daemon.runtime) as lr:
            lt.send(b"near", dst=2)
            assert lr.recv(timeout=30).data == b"near"
            vehicle.position = [300.0, 0.0, 5.0]
            wait_until(lambda: position_on_a() == [300.0, 0.0, 5.0], what="the new pose on A")
            lt.send(b"away", dst=2)
            assert lr.recv(timeout=30).data == b"away"
        A.daemon.stop()
        events = A.events()
        enq = {e["pkt"]: e["t"] for e in events if e.get("ev") == "enq"}
        delays = [round(e["t"] - enq[e["pkt"]], 6) for e in events if e.get("ev") == "rx"]
        # exactly as in the one-host test (test_live_poses): 9 bytes = 72 ms, then 150 m and 300 m at 5 m depth
        assert delays == [round(0.072 + math.hypot(150, 5) / 1500, 6), round(0.072 + math.hypot(300, 5) / 1500, 6)]
    finally:
        vehicle.close()
        A.daemon.close()
        B.daemon.close()


def test_a_clock_offset_shifts_arrivals_and_a_late_one_is_delivered_at_once_and_counted(tmp_path):
    prefix = f"hilgate-test-{uuid.uuid4().hex[:8]}"
    a, b = unique("oa"), unique("ob")
    # slow sound (1 s of flight at 150 m) and a 2 s offset: B's arrivals keep 3 s of slack for a busy host
    # to hear the transmission in, and A's are late by more than a busy host's delay could explain
    speed, offset = 150.0, 2.0
    scene = two_hosts_scene(f"prefix: {prefix}, credentials: {CREDS}", a, b, speed, 1000)
    pa = free_port()
    A = Host(tmp_path, "A", scene, [a], pa)
    B = Host(tmp_path, "B", scene, [b], free_port(), [pa], extra=("--clock-offset-s", str(-offset)))
    try:
        A.daemon.wait_for("READY=1")
        B.daemon.wait_for("READY=1")
        wait_until(lambda: A.sees("B") and B.sees("A"), what="the hosts to meet")
        with Link.open(a, runtime_dir=A.daemon.runtime) as la, Link.open(b, runtime_dir=B.daemon.runtime) as lb:
            la.send(b"A to B", dst=2)  # B's clock is 2 s behind: the frame arrives 2 s later there
            assert lb.recv(timeout=30).data == b"A to B"
            lb.send(b"B to A", dst=1)  # and B's frames are 2 s early at A: past their end, so late
            assert la.recv(timeout=30).data == b"B to A"
            wait_until(lambda: next(h for h in A.status()["network"]["hosts"] if h["host"] == "B")["late"] == 1,
                       what="the late arrival counted")
        A.daemon.stop()
        B.daemon.stop()
        tx_a = next(e["t"] for e in A.events() if e.get("ev") == "tx")
        rx_b = next(e for e in B.events() if e.get("ev") == "rx")
        flight = 150 / speed + rx_b["size"] * 8 / 1000
        assert rx_b["t"] == pytest.approx(to_host(tx_a, A, B) + flight, abs=1e-6)  # B's own view: exact
        real_epoch_b = B.epoch_ns() + round(offset * 1e9)  # the offset the daemon was told to pretend
        assert to_host(tx_a, A, B) - (tx_a + (A.epoch_ns() - real_epoch_b) * 1e-9) == pytest.approx(offset, abs=1e-6)
        late = [e for e in A.events() if e.get("ev") == "late"]
        assert len(late) == 1 and late[0]["link"] == a and late[0]["host"] == "B"
        tx_b = next(e["t"] for e in B.events() if e.get("ev") == "tx")
        rx_a = next(e for e in A.events() if e.get("ev") == "rx")
        should_end = to_host(tx_b, B, A) + 150 / speed + rx_a["size"] * 8 / 1000
        assert late[0]["lateness_s"] == pytest.approx(rx_a["t"] - should_end, abs=1e-6)
        assert late[0]["lateness_s"] > offset - flight - 0.001  # at least what the offset did
    finally:
        A.daemon.close()
        B.daemon.close()


def test_a_scene_with_zenoh_but_no_host_names_is_all_this_daemons(tmp_path):
    """No ``host:`` anywhere: every link is this daemon's, none is another host's (none is host_down)."""
    a, b = unique("sa"), unique("sb")
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
zenoh: {{prefix: hilgate-test-{uuid.uuid4().hex[:8]}, credentials: {CREDS}}}
vehicles: {{va: {{pose: {{static: [0, 0, 0]}}}}, vb: {{pose: {{static: [150, 0, 0]}}}}}}
links:
  {a}: {{vehicle: va, address: 1, bitrate_bps: 1000, addressing: strict}}
  {b}: {{vehicle: vb, address: 2, bitrate_bps: 1000, addressing: strict}}
"""
    host = Host(tmp_path, "solo", scene, [a, b], free_port())
    try:
        host.daemon.wait_for("READY=1")
        assert host.status()["network"]["remote_links"] == []
        with Link.open(a, runtime_dir=host.daemon.runtime) as la, Link.open(b, runtime_dir=host.daemon.runtime) as lb:
            la.send(b"mine", dst=2)
            assert lb.recv(timeout=30).data == b"mine"
        assert host.daemon.link_status(a)["drop_causes"] == {}
    finally:
        host.daemon.close()


def test_an_insecure_network_is_asked_for_warned_about_and_still_checks_what_it_hears(tmp_path):
    """``insecure: true``: plain TCP, a warning at start; a peer without credentials then reaches the
    daemon, and what it forges (a host nobody named, a host speaking for another, times a day away,
    garbage, strangers' tokens, reports of what it heard) is counted or ignored, never a traceback.  Without ``insecure`` or
    credentials the same scene does not start."""
    import json as json_

    import zenoh

    from hilgate.core.backend import AppFrame
    from hilgate.core.packets import packet_class
    from hilgate.daemon.netcodec import encode_transmission
    from hilgate.daemon.netledger import encode_report
    from hilgate.models.frame import Frame

    prefix = f"hilgate-test-{uuid.uuid4().hex[:8]}"
    a, b = unique("fa"), unique("fb")
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
zenoh: {{prefix: {prefix}, insecure: true}}
vehicles: {{va: {{pose: {{static: [0, 0, 0]}}}}, vb: {{pose: {{static: [150, 0, 0]}}}}}}
links:
  {a}: {{vehicle: va, host: A, address: 1, bitrate_bps: 1000}}
  {b}: {{vehicle: vb, host: B, address: 2, bitrate_bps: 1000}}
"""
    refused = Host(tmp_path / "refused", "A", scene.replace(", insecure: true", ""), [a], free_port(), scheme="tcp")
    assert refused.daemon.process.wait(30) != 0
    assert "zenoh: {credentials: DIR}" in refused.daemon.output() and "Traceback" not in refused.daemon.output()
    refused.daemon.close()
    port = free_port()
    host = Host(tmp_path, "A", scene, [a], port, scheme="tcp")
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", '[]')
    config.insert_json5("connect/endpoints", json_.dumps([f"tcp/127.0.0.1:{port}"]))
    try:
        host.daemon.wait_for("READY=1")
        assert "INSECURE network" in host.daemon.output()
        session = zenoh.open(config)
        try:
            token = session.liveliness().declare_token(f"{prefix}/alive/stranger/host/0123")
            vl2b = packet_class("vl2b")
            frame = Frame(1, b, a, 1, 9, 0.0, app_frame=AppFrame(vl2b.encode(b"x", 2, 1), b"x", vl2b, 1, 2, 1, 0.0))
            frame.src_addr = 2
            publishers = {h: session.declare_publisher(f"{prefix}/tx/{h}/ac") for h in "ZBA"}
            wait_until(lambda: all(p.matching_status.matching for p in publishers.values()), what="the daemon's subscriber")
            publishers["Z"].put(encode_transmission("Z", 0, 1, frame, 0.0, 0.1, None))         # a host nobody named
            publishers["B"].put(encode_transmission("B", time.time_ns(), 1, frame, 86400.0, 0.1, None))  # a day ahead
            publishers["B"].put(b"\x00\x00\x00\x05garbage")                                   # not a message
            publishers["A"].put(encode_transmission("B", time.time_ns(), 2, frame, 0.0, 0.1, None))  # A speaking for B
            # reports of what a host heard (hilgate/daemon/netledger.py): of a host nobody named, not one, and
            # one under B's key that says it is A's; none settles anything
            report = encode_report("Z", "zz", "s", 1, 1, 5, [[1, 5]], [], False)
            session.put(f"{prefix}/ack/Z/A", report)
            session.put(f"{prefix}/ack/B/A", b"[[[[")
            session.put(f"{prefix}/ack/B/A", report.replace(b'"h":"Z"', b'"h":"A"'))
            want = {"foreign_sender": 2, "out_of_time": 1, "bad_message": 2, "forged": 2}
            counters = wait_until(lambda: (lambda c: c if sum(c.values()) >= sum(want.values()) else None)(
                host.status()["network"]["counters"]), what="the counters")
            assert counters == want
            assert {v["host"] for v in host.status()["network"]["hosts"]} == {"B"}  # no stranger
            token.undeclare()
        finally:
            session.close()
        assert host.daemon.process.poll() is None
        host.daemon.stop()
        assert "Traceback" not in host.daemon.output()
        assert not [e for e in host.events() if e.get("ev") in ("rx", "late")]
    finally:
        host.daemon.close()
