"""One sender's flood holds back no other (issue 37, item 1): the Zenoh door and the ROS 2 door take
their senders' frames in turn, so an honest application's frames cross while another floods the same
link, and a flood of senders cannot take the places of the others.

Each test floods a real daemon's link on loopback until the honest sender's 40 frames (sent at once,
once the flood fills its queue at the door) have all arrived, in order, at the other link's
application, and checks the order they crossed in: flood frames before the first honest one and after
the last (the flood was on all along), and between them about one of the flood's per honest frame, as
turns would have it.  The links are slow (a frame is tens of milliseconds on air) so that a loaded
machine's delays are worth a few frames of slack, never a turn's worth of frames.  Nothing is timed:
the only bound is the kit's hang guard.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import pytest

from daemon_kit import HANG_GUARD_S, unique, wait_until  # noqa: E402
from hilgate.client import Link  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
HONEST = 40


def honest_order(received: list[bytes]) -> list[bytes]:
    return [data for data in received if data.startswith(b"honest")]


def read_until_honest(link, received: list[bytes], flood_marker: bytes) -> None:
    """Read ``link`` until every honest frame came, then until one more frame of the flood came (the
    whole read bounded by the hang guard: a flood that keeps coming is no progress)."""
    deadline = time.monotonic() + HANG_GUARD_S

    def more() -> bytes:
        message = link.recv(timeout=max(0.0, deadline - time.monotonic()))
        assert message is not None and time.monotonic() < deadline, (
            f"timed out after {HANG_GUARD_S:g} s: {len(honest_order(received))} honest frames of {HONEST} "
            f"during the flood, {len(received)} frames in all")
        received.append(bytes(message.data))
        return received[-1]

    while len(honest_order(received)) < HONEST:
        more()
    while not more().startswith(flood_marker):
        pass


def assert_fair(received: list[bytes], flood_marker: bytes) -> int:
    """The honest frames in order, during the flood, taking turns with it; returns the flood's frames
    between the first honest frame and the last."""
    assert honest_order(received) == [b"honest %d" % i for i in range(HONEST)]
    first = received.index(b"honest 0")
    last = received.index(b"honest %d" % (HONEST - 1))
    assert any(d.startswith(flood_marker) for d in received[:first]), "the flood was on before the honest frames"
    assert any(d.startswith(flood_marker) for d in received[last:]), "and still on after them"
    between = sum(1 for d in received[first:last] if d.startswith(flood_marker))
    assert between <= 2 * HONEST, f"{between} flood frames crossed between the first honest frame and the last"
    return between


# -- the Zenoh door --------------------------------------------------------------------------------------

zenoh = pytest.importorskip("zenoh")

from test_netauth import Lab, attacker, creds, peers  # noqa: E402, F401 (creds: a fixture)


ZENOH_BITRATE_BPS = 5000
"""The Zenoh test's link: a flood frame (50 bytes) is 88 ms on air, an honest one about 20."""


@pytest.fixture
def lab(tmp_path, creds):  # noqa: F811
    lab = Lab(tmp_path, creds, bitrate_bps=ZENOH_BITRATE_BPS)
    yield lab
    lab.close()


def test_an_application_flooding_the_zenoh_door_holds_back_no_other(lab):
    """app-2 floods link a with SENDs (under its own credentials) for as long as the test runs; app-1 sends
    40 frames meanwhile: all 40 reach link b's application during the flood, in order, taking turns."""
    A = lab.hosts["A"]
    flooder = attacker(lab.ports[0], os.path.join(lab.creds, "apps", "app-2"))
    stop = threading.Event()
    sent = [0]

    def flood() -> None:
        publisher = flooder.declare_publisher(f"{lab.prefix}/link/A/{lab.a}/send/app-2")
        payload = b"\x02" + b"F" * 50  # to link b's address, as the honest frames
        while not stop.is_set():
            publisher.put(payload)
            sent[0] += 1

    thread = threading.Thread(target=flood)
    received: list[bytes] = []
    try:
        wait_until(lambda: peers(flooder), what="the flooder to connect")
        with lab.app(lab.a) as honest, Link.open(lab.b, runtime_dir=lab.hosts["B"].daemon.runtime) as lb:
            thread.start()
            wait_until(lambda: A.daemon.link_status(lab.a)["drop_causes"].get("client_queue", 0)
                       + A.daemon.link_status(lab.a)["drop_causes"].get("rate", 0) > 0,
                       what="the flood to fill its queue at the door")
            for i in range(HONEST):
                honest.send(b"honest %d" % i, dst=2)
            read_until_honest(lb, received, b"F")
    finally:
        stop.set()
        if thread.is_alive():
            thread.join()
        flooder.close()
    between = assert_fair(received, b"F")
    print(f"zenoh door: {between} flood frames crossed between the first honest frame and the last")
    causes = A.daemon.link_status(lab.a)["drop_causes"]
    assert causes.get("rate", 0) + causes.get("client_queue", 0) > 0, causes  # the flood lost its own excess
    assert "clients" not in causes


def test_a_flood_of_client_names_takes_no_honest_clients_place(tmp_path):
    """Without credentials (``insecure``) a client is whatever name it gives: one session floods a link
    under 32 names at once, every place at the door.  An honest client's 40 frames all cross all the
    same: a newcomer takes the place of a client over its share (``evicted``: the flood's names take
    each other's), and the honest client, within its share, keeps its place."""
    import json as json_
    import uuid

    from test_multihost import Host, free_port

    prefix = f"hilgate-test-{uuid.uuid4().hex[:8]}"
    a, b = unique("ea"), unique("eb")
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
zenoh: {{prefix: {prefix}, insecure: true}}
vehicles: {{va: {{pose: {{static: [0, 0, 0]}}}}, vb: {{pose: {{static: [150, 0, 0]}}}}}}
links:
  {a}: {{vehicle: va, address: 1, bitrate_bps: 100000, addressing: strict}}
  {b}: {{vehicle: vb, address: 2, bitrate_bps: 100000, addressing: strict}}
"""
    port = free_port()
    host = Host(tmp_path, "solo", scene, [a, b], port, scheme="tcp")
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("connect/endpoints", json_.dumps([f"tcp/127.0.0.1:{port}"]))
    stop = threading.Event()
    received: list[bytes] = []
    try:
        host.daemon.wait_for("READY=1")
        flooder = zenoh.open(config)
        publishers = [flooder.declare_publisher(f"{prefix}/link/solo/{a}/send/flood-{i}") for i in range(32)]

        def flood() -> None:
            payload = b"\x02" + b"F" * 50
            while not stop.is_set():
                for publisher in publishers:
                    publisher.put(payload)

        thread = threading.Thread(target=flood)
        with Link.open(a, zenoh={"connect": [f"tcp/127.0.0.1:{port}"], "prefix": prefix}, timeout=30) as honest, \
                Link.open(b, runtime_dir=host.daemon.runtime) as lb:
            thread.start()
            wait_until(lambda: host.daemon.link_status(a)["drop_causes"].get("client_queue", 0) > 32 * 64,
                       what="the 32 names to fill their queues")
            for i in range(HONEST):
                honest.send(b"honest %d" % i, dst=2)
            try:
                read_until_honest(lb, received, b"F")
            finally:
                stop.set()
                thread.join()
        flooder.close()
        assert honest_order(received) == [b"honest %d" % i for i in range(HONEST)]  # none refused, none evicted
        causes = host.daemon.link_status(a)["drop_causes"]
        assert causes.get("evicted", 0) > 0, causes  # the flood's names took each other's places
        print(f"zenoh door, 32 names: {causes}")
    finally:
        stop.set()
        host.daemon.close()


# -- the ROS 2 door ----------------------------------------------------------------------------------------

cyclonedds = pytest.importorskip("cyclonedds")

from ros2kit import DOMAIN, Publication, dds, namespace, node_and_app_scene  # noqa: E402, F401 (dds: a fixture)
from hilgate.ros2.idl import message_class  # noqa: E402

BITRATE_BPS = 2000
"""The ROS 2 test's link: a flood frame (20 bytes) is 100 ms on air, so a writer at 1 000 frames a second
keeps its queue at the door full."""


@pytest.mark.parametrize("writers, rate", [(1, 1000), (1, 5000), (32, 0)],
                         ids=["one writer at 1000 Hz", "one writer at 5000 Hz", "32 writers flat out"])
def test_a_node_flooding_the_ros2_door_holds_back_no_other(daemon_of, dds, writers, rate):  # noqa: F811
    """Another process (a DDS participant of its own) floods the node link's ``send`` topic with
    ``writers`` writers; this test's node sends 40 frames meanwhile: all 40 reach the application on the
    other link during the flood, in order, taking turns with the flood (one turn for the other process,
    however many writers it has), and none is refused for want of a place at the door."""
    ns = namespace()
    node_link, app_link = unique("fn"), unique("fa")
    Frame = message_class("hilgate_msgs/msg/Frame")
    send = dds(Publication(f"{ns}/{node_link}/send", "hilgate_msgs/msg/Frame"))
    daemon = daemon_of(node_and_app_scene(ns, node_link, app_link, 15, BITRATE_BPS, ", gli: [socket]"),
                       [node_link, app_link])
    flooder = subprocess.Popen([sys.executable, os.path.join(HERE, "peers", "dds_flooder.py"), str(DOMAIN),
                                f"{ns}/{node_link}/send", "--writers", str(writers), "--rate", str(rate)],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    received: list[bytes] = []
    try:
        with Link.open(app_link, runtime_dir=daemon.runtime) as application:
            assert flooder.stdout.readline().strip() == "matched"
            wait_until(send.matched, what="hilgate's reader of the send topic")
            wait_until(lambda: daemon.link_status(node_link)["drop_causes"].get("client_queue", 0)
                       + daemon.link_status(node_link)["drop_causes"].get("rate", 0) > 0,
                       what="the flood to fill its queue at the door")
            for i in range(HONEST):
                send.write(Frame(dst=2, data=b"honest %d" % i))
            read_until_honest(application, received, b"F")
    finally:
        flooder.stdin.close()
        flooder.wait(HANG_GUARD_S)
    between = assert_fair(received, b"F")
    print(f"ros2 door, {writers} writers at {rate or 'full speed'}: {between} flood frames crossed between the "
          f"first honest frame and the last")
    causes = daemon.link_status(node_link)["drop_causes"]
    assert "clients" not in causes, causes
    assert daemon.process.poll() is None and "Traceback" not in daemon.output()
