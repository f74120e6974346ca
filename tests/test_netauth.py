"""A network of daemons under attack: a third Zenoh session on loopback, with no credentials, with
another host's, with an application's, tries what issue 23 found open (forged and replayed frames,
forged liveliness, floods).  Each attack must fail, and be counted where the daemon can see it.

The attacker is a bare Zenoh session built here (TLS with the certificate it holds, no access control
of its own: it may try anything); what stops it is the daemons' configuration, never the attacker's.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import threading
import time
import uuid

import pytest

from daemon_kit import unique  # noqa: E402
from hilgate.client import Link  # noqa: E402
from test_multihost import Host, free_port, two_hosts_scene, wait_until  # noqa: E402

zenoh = pytest.importorskip("zenoh")

SPEED = 1500.0


@pytest.fixture(scope="module")
def creds(tmp_path_factory):
    from hilgate.netinit import init_network

    root = str(tmp_path_factory.mktemp("creds"))
    init_network(root, ["A", "B", "C"], 2)
    foreign = str(tmp_path_factory.mktemp("foreign"))
    init_network(foreign, ["A", "B"], 1)  # the same names, another CA
    return {"root": root, "foreign": foreign}


def scene_text(prefix: str, creds: str, a: str, b: str, extra: str = "", bitrate_bps: float = 100000) -> str:
    return two_hosts_scene(f"prefix: {prefix}, lease_s: 5, credentials: {creds}{extra}", a, b, SPEED, bitrate_bps)


class Lab:
    def __init__(self, tmp_path, creds: dict, start_b: bool = True, extra: str = "", bitrate_bps: float = 100000):
        self.tmp = tmp_path
        self.creds = creds["root"]
        self.foreign = creds["foreign"]
        self.prefix = f"hilgate-test-{uuid.uuid4().hex[:8]}"
        self.a, self.b = unique("xa"), unique("xb")
        self.scene = scene_text(self.prefix, self.creds, self.a, self.b, extra, bitrate_bps)
        self.ports = [free_port(), free_port()]
        self.hosts: dict[str, Host] = {"A": Host(tmp_path, "A", self.scene, [self.a], self.ports[0])}
        self.hosts["A"].daemon.wait_for("READY=1")
        if start_b:
            self.start_b()

    def start_b(self, where: str = "B") -> Host:
        host = self.hosts["B"] = Host(self.tmp / where, "B", self.scene, [self.b], self.ports[1], [self.ports[0]])
        host.daemon.wait_for("READY=1")
        wait_until(lambda: self.hosts["A"].sees("B") and host.sees("A"), what="A and B to meet")
        return host

    def counters(self, host: str = "A") -> dict:
        return self.hosts[host].status()["network"]["counters"]

    def app(self, link: str, name: str = "app-1", host_port: int | None = None):
        port = self.ports[0] if host_port is None else host_port
        return Link.open(link, zenoh={"connect": [f"tls/127.0.0.1:{port}"], "prefix": self.prefix,
                                      "credentials": os.path.join(self.creds, "apps", name)}, timeout=30)

    def close(self) -> None:
        for host in self.hosts.values():
            host.daemon.close()


@pytest.fixture
def lab(tmp_path, creds):
    lab = Lab(tmp_path, creds)
    yield lab
    lab.close()


def attacker(port: int, identity_dir: str | None = None, tls: bool = True, ca: str | None = None):
    """A Zenoh peer of our own: TLS with the certificate in ``identity_dir`` (or none), no ACL."""
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("connect/endpoints", json.dumps([f"{'tls' if tls else 'tcp'}/127.0.0.1:{port}"]))
    if tls:
        tls_config = {"root_ca_certificate": ca or os.path.join(identity_dir, "ca.pem"),
                      "verify_name_on_connect": False}
        if identity_dir is not None:
            tls_config.update(connect_certificate=os.path.join(identity_dir, "cert.pem"),
                              connect_private_key=os.path.join(identity_dir, "key.pem"), enable_mtls=True)
        config.insert_json5("transport/link/tls", json.dumps(tls_config))
    return zenoh.open(config)


@contextlib.contextmanager
def intruder(lab, credentials: str, *overheard: str):
    """Two sessions with the credentials ``credentials`` (``hosts/C``, ``apps/app-2``) on host A's port, both let
    in: one that speaks, and one that listens on the keys ``overheard`` (under the lab's prefix: a session
    hears its own puts, so it is another one).  Yields the speaker and the keys heard; closes both after."""
    speaker, listener = (attacker(lab.ports[0], os.path.join(lab.creds, credentials)) for _ in range(2))
    heard: list[str] = []
    try:
        wait_until(lambda: peers(speaker) and peers(listener), what=f"{credentials} to be let in")
        for key in overheard:
            listener.declare_subscriber(f"{lab.prefix}/{key}", lambda s: heard.append(str(s.key_expr)))
        yield speaker, heard
    finally:
        speaker.close()
        listener.close()


def peers(session) -> list:
    return list(session.info.peers_zid())


def transmission(host: str, src: str, dst: str, payload: bytes, number: int = 1, session: str = "abc",
                 kind: str = "data", epoch_ns: int | None = None) -> bytes:
    """A transmission as a daemon of ``host`` would publish it (``src`` → ``dst``, vl2b, address 2 → 1)."""
    from hilgate.core.backend import AppFrame
    from hilgate.core.packets import packet_class
    from hilgate.daemon.netcodec import encode_transmission
    from hilgate.models.frame import Frame

    vl2b = packet_class("vl2b")
    real = vl2b.encode(payload, 2, 1)
    frame = Frame(number, src, dst, 1, len(real), 0.0, kind=kind,
                  app_frame=AppFrame(real, payload, vl2b, number, 2, 1, 0.0))
    frame.src_addr = 2
    # t: now on the sender's model clock, with the sender's epoch 1 s ago
    epoch = epoch_ns if epoch_ns is not None else time.time_ns() - 1_000_000_000
    return encode_transmission(host, epoch, number, frame, (time.time_ns() - epoch) * 1e-9, 0.001, None, session)


# -- no credentials --------------------------------------------------------------------------------------


def test_without_credentials_a_peer_cannot_even_connect(lab):
    port = lab.ports[0]
    strangers = [attacker(port, tls=False),                                              # plain TCP
                 attacker(port, ca=os.path.join(lab.creds, "ca", "ca.pem")),             # TLS, no certificate
                 attacker(port, os.path.join(lab.foreign, "hosts", "A"))]                # another lab's "A"
    member = attacker(port, os.path.join(lab.creds, "apps", "app-2"))                   # the control
    try:
        wait_until(lambda: peers(member), what="a session with the lab's credentials to connect")
        time.sleep(1.0)  # (as long again for the strangers: a TLS handshake on loopback takes milliseconds)
        assert [peers(s) for s in strangers] == [[], [], []]
        for session in strangers:  # what they say goes nowhere
            session.put(f"{lab.prefix}/tx/B/ac", transmission("B", lab.b, lab.a, b"forged"))
            session.liveliness().declare_token(f"{lab.prefix}/alive/B/host/0123")
        assert lab.hosts["A"].sees("B")
        assert lab.hosts["A"].daemon.link_status(lab.a)["rx_packets"] == 0
    finally:
        for session in (*strangers, member):
            session.close()


# -- another host's credentials ----------------------------------------------------------------------------


def test_another_hosts_credentials_cannot_speak_for_a_host_or_reach_applications(lab):
    A = lab.hosts["A"]
    with intruder(lab, "hosts/C", "link/**") as (evil, heard):  # C's certificate: a host of the lab
        with lab.app(lab.a) as la, Link.open(lab.b, runtime_dir=lab.hosts["B"].daemon.runtime) as lb:
            # as host B, a frame from B's link to A's: refused by A's access control
            evil.put(f"{lab.prefix}/tx/B/ac", transmission("B", lab.b, lab.a, b"forged as B"))
            # under its own name, saying it is B: let in, and counted
            evil.put(f"{lab.prefix}/tx/C/ac", transmission("B", lab.b, lab.a, b"forged by C"))
            # a RECV to the application on link a, as if A had delivered it: refused by the application's session
            evil.put(f"{lab.prefix}/link/A/{lab.a}/recv", b"\x02\x01" + bytes(8) + b"forged recv")
            # a command as the application (a host may not query link keys)
            assert not [r for r in evil.get(f"{lab.prefix}/link/A/{lab.a}/command/app-1",
                                            payload=b'{"class": "POSE"}', timeout=2.0) if r.ok is not None]
            wait_until(lambda: lab.counters().get("forged") == 1, what="C's frame as B counted")
            lb.send(b"genuine", dst=1)  # the control: B's own frame arrives
            message = la.recv(timeout=30)
            assert (message.src, message.data) == (2, b"genuine")
            assert la.recv(timeout=1.0) is None
        assert A.daemon.link_status(lab.a)["rx_packets"] == 1
        assert heard == []  # C subscribed to every link key, and heard no frame of A's
        assert next(h for h in A.status()["network"]["hosts"] if h["host"] == "B")["heard"] == 1


# -- an application's credentials --------------------------------------------------------------------------


def test_an_applications_credentials_reach_link_keys_only(lab):
    A = lab.hosts["A"]
    with intruder(lab, "apps/app-2", "tx/**", "pose/**") as (app, heard):
        app.liveliness().declare_token(f"{lab.prefix}/alive/A/host/0123")
        app.put(f"{lab.prefix}/tx/B/ac", transmission("B", lab.b, lab.a, b"forged by an app"))
        app.put(f"{lab.prefix}/link/A/{lab.a}/send/app-1", b"\x02as app-1")  # under another app's name
        assert not [r for r in app.get(f"{lab.prefix}/status/*", timeout=2.0) if r.ok is not None]
        assert not [r for r in app.liveliness().get(f"{lab.prefix}/alive/**", timeout=2.0) if r.ok is not None]
        app.put(f"{lab.prefix}/link/A/{lab.a}/send/app-2", b"\x02its own")  # allowed: its own SEND
        wait_until(lambda: A.daemon.link_status(lab.a)["tx_packets"] == 1, what="app-2's own SEND")
        with Link.open(lab.b, runtime_dir=lab.hosts["B"].daemon.runtime) as lb:
            lb.send(b"after", dst=1)  # something goes on air, so the subscriptions would have heard it
            wait_until(lambda: A.daemon.link_status(lab.a)["rx_packets"] == 1, what="B's frame at A")
        assert A.daemon.link_status(lab.a)["tx_packets"] == 1  # not the one as app-1
        assert heard == []
        assert A.sees("B") and lab.counters().get("forged") is None
        assert [h["host"] for h in A.status()["network"]["hosts"]] == ["B"]


# -- forged liveliness -------------------------------------------------------------------------------------


@pytest.mark.parametrize("who", ["hosts/C", "apps/app-2"])
def test_forged_tokens_neither_block_a_start_nor_keep_a_dead_host_up(tmp_path, creds, who):
    lab = Lab(tmp_path, creds, start_b=False)
    evil = attacker(lab.ports[0], os.path.join(lab.creds, who))
    try:
        A = lab.hosts["A"]
        wait_until(lambda: peers(evil), what="the attacker to be let in")
        zid = "0123456789abcdef"
        tokens = [evil.liveliness().declare_token(f"{lab.prefix}/alive/B/host/{zid}"),
                  evil.liveliness().declare_token(f"{lab.prefix}/alive/B/link/{lab.b}/{zid}")]
        with Link.open(lab.a, runtime_dir=A.daemon.runtime) as la:
            la.send(b"to nobody yet", dst=2)
            wait_until(lambda: A.daemon.link_status(lab.a)["drop_causes"].get("host_down") == 1,
                       what="a frame to B counted host_down while only forged tokens exist")
        assert not A.sees("B")
        B = lab.start_b()  # not refused: the tokens under B's name are not B's
        assert B.daemon.process.poll() is None and A.remote_link(lab.b) == "up"
        B.daemon.process.send_signal(signal.SIGKILL)
        B.daemon.process.wait()
        wait_until(lambda: A.remote_link(lab.b) == "down", what="B seen down despite the forged tokens")
        with Link.open(lab.a, runtime_dir=A.daemon.runtime) as la:
            la.send(b"to a dead host", dst=2)
            wait_until(lambda: A.daemon.link_status(lab.a)["drop_causes"].get("host_down") == 2,
                       what="the frame to dead B counted host_down")
        for token in tokens:
            token.undeclare()
    finally:
        evil.close()
        lab.close()


# -- integrity and replays ---------------------------------------------------------------------------------


def test_replayed_and_damaged_transmissions_are_dropped_and_counted(lab):
    """Even with B's own certificate (a stolen key, or a host turned bad): what B said once is not
    heard twice, and a copy with bits changed is refused."""
    A = lab.hosts["A"]
    thief = attacker(lab.ports[0], os.path.join(lab.creds, "hosts", "B"))
    listener = attacker(lab.ports[0], os.path.join(lab.creds, "hosts", "B"))  # (a session hears its own puts)
    captured: list[tuple[str, bytes]] = []
    try:
        wait_until(lambda: peers(thief) and peers(listener), what="the thief to connect")
        listener.declare_subscriber(f"{lab.prefix}/tx/B/**",
                                    lambda s: captured.append((str(s.key_expr), s.payload.to_bytes())))
        with lab.app(lab.a) as la, Link.open(lab.b, runtime_dir=lab.hosts["B"].daemon.runtime) as lb:
            for i in range(3):
                lb.send(b"genuine %d" % i, dst=1)
                assert la.recv(timeout=30).data == b"genuine %d" % i
            wait_until(lambda: len(captured) >= 3, what="the thief to capture B's transmissions")
            listener.close()
            for key, data in captured:  # replayed as they were, under B's name
                thief.put(key, data)
            key, data = captured[-1]
            damaged = bytearray(data)
            damaged[len(damaged) // 2] ^= 0x10
            thief.put(key, bytes(damaged))
            wait_until(lambda: lab.counters().get("replay", 0) == len(captured) and lab.counters().get("damaged") == 1,
                       what="the replays and the damaged copy counted")
            assert la.recv(timeout=1.0) is None
        assert A.daemon.link_status(lab.a)["rx_packets"] == 3
        view = next(h for h in A.status()["network"]["hosts"] if h["host"] == "B")
        assert view["gaps"] == 0 and view["heard"] == 3
    finally:
        thief.close()
        listener.close()
    A.daemon.stop()
    replays = [e for e in A.events() if e.get("cause") == "replay"]
    assert len(replays) == len(captured) and all(e["src"] == "B" for e in replays)


# -- floods ------------------------------------------------------------------------------------------------


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as handle:
        for line in handle:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


FLOOD_BOUND_MB = 64.0
"""What a flood may add to a daemon's memory: the Zenoh door holds at most 16 MiB of SENDs
(zenoh_door.DOOR_BYTES), the transmissions' FIFO and the inboxes a few MiB at these sizes; the rest
is Python's and Zenoh's working memory under load."""


def test_a_flood_of_sends_costs_an_honest_application_nothing(lab):
    """app-2 floods link a with SENDs as fast as Zenoh takes them; app-1 on link a sends 40 frames meanwhile,
    and the application on link b gets every one of them.  The daemon's memory stays within the bound."""
    A = lab.hosts["A"]
    pid = A.daemon.process.pid
    baseline = rss_mb(pid)
    flooder = attacker(lab.ports[0], os.path.join(lab.creds, "apps", "app-2"))
    stop = threading.Event()
    sent = [0]
    peak = [baseline]

    def flood() -> None:
        publisher = flooder.declare_publisher(f"{lab.prefix}/link/A/{lab.a}/send/app-2")
        payload = b"\x07" + b"F" * 200  # to address 7: nobody's (strict addressing), still on air
        while not stop.is_set() and sent[0] < 2_000_000:
            publisher.put(payload)
            sent[0] += 1

    def watch() -> None:
        while not stop.is_set():
            peak[0] = max(peak[0], rss_mb(pid))
            time.sleep(0.05)

    try:
        wait_until(lambda: peers(flooder), what="the flooder to connect")
        with lab.app(lab.a) as honest, Link.open(lab.b, runtime_dir=lab.hosts["B"].daemon.runtime) as lb:
            threads = [threading.Thread(target=flood), threading.Thread(target=watch)]
            for thread in threads:
                thread.start()
            wait_until(lambda: sent[0] > 20000, what="the flood to start")
            for i in range(40):
                honest.send(b"honest %d" % i, dst=2)
                time.sleep(0.02)
            got = []
            while len(got) < 40:
                message = lb.recv(timeout=60)
                assert message is not None, f"only {len(got)} honest frames of 40"
                got.append(message.data)
            stop.set()
            for thread in threads:
                thread.join()
        assert got == [b"honest %d" % i for i in range(40)]
        causes = A.daemon.link_status(lab.a)["drop_causes"]
        assert causes.get("rate", 0) + causes.get("client_queue", 0) > 0, causes
        assert "fifo" not in causes
        assert peak[0] - baseline < FLOOD_BOUND_MB, (baseline, peak[0])
        assert A.sees("B") and lab.hosts["B"].sees("A")
    finally:
        stop.set()
        flooder.close()
    print(f"flood: {sent[0]} SENDs; daemon RSS {baseline:.0f} MB -> peak {peak[0]:.0f} MB; "
          f"after {rss_mb(pid):.0f} MB; drops {A.daemon.link_status(lab.a)['drop_causes']}")


def test_a_query_flood_keeps_the_daemons_talking(lab):
    """16 threads asking link a's command queryable as fast as they can (the issue's flood made both
    daemons declare each other down): the daemons keep seeing each other, an honest command is answered."""
    A = lab.hosts["A"]
    flooder = attacker(lab.ports[0], os.path.join(lab.creds, "apps", "app-2"))
    stop = threading.Event()
    asked = [0]

    def ask() -> None:
        while not stop.is_set() and asked[0] < 200_000:
            for _ in flooder.get(f"{lab.prefix}/link/A/{lab.a}/command/app-2", payload=b'{"class": "POSE"}',
                                 timeout=0.5):
                pass
            asked[0] += 1

    B = lab.hosts["B"]
    views = []

    def watch() -> None:  # what each daemon thinks of the other, all along the flood
        while not stop.is_set():
            views.append((A.sees("B"), B.sees("A")))
            time.sleep(0.05)

    try:
        wait_until(lambda: peers(flooder), what="the flooder to connect")
        threads = [threading.Thread(target=ask) for _ in range(16)] + [threading.Thread(target=watch)]
        for thread in threads:
            thread.start()
        wait_until(lambda: asked[0] > 500, what="the query flood to run")
        with lab.app(lab.a) as honest:
            assert honest.command({"class": "POSE"})["position"] == [0.0, 0.0, 0.0]
        wait_until(lambda: asked[0] > 2000, what="more of the flood")
        stop.set()
        for thread in threads:
            thread.join()
        assert A.daemon.link_status(lab.a)["drop_causes"].get("query_refused", 0) > 0
        assert views and all(a and b for a, b in views), views
    finally:
        stop.set()
        flooder.close()
    B.daemon.stop()  # (B first: A then sees it go down, but only once the flood is over)
    assert [e["state"] for e in B.events() if e.get("ev") == "host"] == ["up"]  # A: up once, never down


# -- the trace stays JSON lines ---------------------------------------------------------------------------


def test_fuzzed_network_messages_leave_every_trace_line_json(lab):
    """With B's key (stolen), 3 000 messages on B's transmission key: real ones with names and kinds
    that are not (the issue's ``"dat\\x00"``, quotes, newlines, Unicode), real ones with bytes changed and
    the CRC made to match, and plain damage.  The daemon goes on, counts them, and every line of its
    trace parses as JSON."""
    import random
    import struct
    import zlib

    A = lab.hosts["A"]
    thief = attacker(lab.ports[0], os.path.join(lab.creds, "hosts", "B"))
    rng = random.Random(23)
    nasty = ["dat\x00", 'a"b', "x\ny", "ü\u2028", "\\", "{", "\x7f", "data ", "", "A" * 300]
    epoch = time.time_ns() - 1_000_000_000
    sent = 0
    try:
        wait_until(lambda: peers(thief), what="the thief to connect")
        publisher = thief.declare_publisher(f"{lab.prefix}/tx/B/ac")
        wait_until(lambda: publisher.matching_status.matching, what="A's subscriber")
        for i in range(3000):
            choice = i % 3
            kind, src = "data", lab.b
            if choice == 0:
                if rng.random() < 0.5:
                    kind = rng.choice(nasty)
                else:
                    src = rng.choice(nasty)
            try:
                blob = transmission("B", src, lab.a, b"fuzz %d" % i, number=10_000 + i, session="f00d",
                                    kind=kind, epoch_ns=epoch)
            except ValueError:  # (a name the encoder itself refuses: too long, empty)
                continue
            if choice == 1:  # bytes changed, CRC made to match
                body = bytearray(blob[:-4])
                for _ in range(rng.randint(1, 4)):
                    body[rng.randrange(len(body))] = rng.randrange(256)
                blob = bytes(body) + struct.pack(">I", zlib.crc32(bytes(body)))
            elif choice == 2:  # plain damage
                damaged = bytearray(blob)
                damaged[rng.randrange(1, len(damaged))] ^= 1 << rng.randrange(8)
                blob = bytes(damaged)
            publisher.put(blob)
            sent += 1
            if i % 200 == 199:
                time.sleep(0.01)  # (paced a little: Zenoh drops what a peer cannot take, and this counts)
        wait_until(lambda: sum(lab.counters().values()) + A.daemon.link_status(lab.a)["rx_packets"] >= sent * 0.9,
                   what="most fuzzed messages accounted for")
        assert A.daemon.process.poll() is None and A.sees("B")
    finally:
        thief.close()
    A.daemon.stop()
    assert "Traceback" not in A.daemon.output()
    lines = A.daemon.trace.read_text().splitlines()
    for line in lines:
        json.loads(line)  # every one
    kinds = {e.get("kind") for e in map(json.loads, lines)}
    assert not kinds & set(nasty)
