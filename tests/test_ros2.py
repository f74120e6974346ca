"""hilgate on ROS 2 (issue 27), against a second Cyclone DDS participant standing in for a ROS 2 node
(tests/ros2kit.py), on loopback, in a DDS domain drawn for this run.

What a ROS 2 node sends moves the channel model (odometry at 50 Hz: the propagation delay of the link
follows exactly, from the trace, as in the MAVLink test); hilgate's poses, ``/tf`` and ``/diagnostics``
arrive; a frame from a "ROS 2 node" reaches a dccomms application and back; hostile samples are counted,
never applied.  tests/test_ros2_wire.py holds the bytes and the type hashes against rosbags.
"""

from __future__ import annotations

import math
import threading

import pytest

from ros2kit import (DOMAIN, Publication, Subscription, dds, namespace, node_and_app_scene,  # noqa: F401 (dds: a fixture)
                     publications, ros2_scene, wait_until)
from daemon_kit import Daemon, assert_the_walk_traced, hilgate, peer_events, unique, walk_a_live_vehicle
from hilgate.client import Link
from hilgate.ros2.idl import message_class
from hilgate.ros2.messages import user_data

Odometry = message_class("nav_msgs/msg/Odometry")


class Simulator:
    """A robot simulator's odometry: ``nav_msgs/msg/Odometry`` in ENU at 50 Hz, until told to stop."""

    def __init__(self, topic: str):
        self.publication = Publication(topic, "nav_msgs/msg/Odometry")
        self.enu = (0.0, 150.0, -5.0)  # 150 m north, 5 m deep
        self.sending = True
        self.sent = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop.is_set():
            if self.sending:
                message = Odometry()
                message.header.frame_id = "odom"
                message.child_frame_id = "base_link"
                p = message.pose.pose.position
                p.x, p.y, p.z = self.enu
                message.pose.pose.orientation.w = 1.0
                self.publication.write(message)
                self.sent += 1
            self.stop.wait(0.02)

    def close(self):
        self.stop.set()
        self.thread.join()
        self.publication.close()


def test_odometry_at_50_hz_moves_the_vehicle_and_the_delay_follows(daemon_of):
    ns = namespace()
    topside, bluerov = unique("top"), unique("rov")
    scene = ros2_scene(ns, f"""\
  topside: {{pose: {{static: [0, 0, 0]}}}}
  bluerov:
    pose: {{ros2: {{topic: {ns}/bluerov/odom, type: nav_msgs/msg/Odometry, frame_id: odom}}}}
    stale_after_s: 1.0
    stale: drop
""", f"""\
  {topside}: {{vehicle: topside, address: 1, bitrate_bps: 1000, addressing: strict}}
  {bluerov}: {{vehicle: bluerov, address: 2, bitrate_bps: 1000, addressing: strict}}
""")
    daemon = daemon_of(scene, [topside, bluerov])
    simulator = Simulator(f"{ns}/bluerov/odom")
    try:
        def stop_the_simulator():  # silence, stale, dropped
            simulator.sending = False

        seen = walk_a_live_vehicle(daemon, topside, bluerov, lambda: setattr(simulator, "enu", (0.0, 300.0, -5.0)),
                                   stop_the_simulator)
        assert seen["source"] == "ros2"  # ENU → NED
        printed = hilgate("status", "--runtime-dir", daemon.runtime).stdout
        assert f"ROS 2: domain {DOMAIN} on loopback, namespace {ns}" in printed and f"{ns}/bluerov/odom" in printed
        ros2 = daemon.status()["ros2"]
        (source,) = ros2["poses_in"]
        assert source["refused"] == {} and source["topic"] == f"{ns}/bluerov/odom"
        assert 0 < source["applied"] <= source["messages"] <= simulator.sent
        assert_the_walk_traced(daemon)
    finally:
        simulator.close()


def test_poses_tf_and_diagnostics_are_published_as_the_scene_asks(daemon_of, dds):
    ns = namespace()
    a, b = unique("a"), unique("b")
    scene = ros2_scene(ns, f"""\
  ship: {{pose: {{static: [10, 20, 0]}}}}
  auv: {{pose: {{path: {{start: [100, 0, 30], legs: [{{to: [100, 50, 30], speed_mps: 0.001}}]}}}}}}
""", f"""\
  {a}: {{vehicle: ship, address: 1, gli: [socket]}}
  {b}: {{vehicle: auv, address: 2, gli: [socket]}}
""", '''  frame_id: map
  publish:
    poses: {rate_hz: 20}
    tf: {rate_hz: 20, reliability: best_effort}
    diagnostics: {rate_hz: 5}
''')
    ship = dds(Subscription(f"{ns}/ship/pose", "geometry_msgs/msg/PoseStamped"))
    tf = dds(Subscription("/tf", "tf2_msgs/msg/TFMessage", "best_effort"))
    diagnostics = dds(Subscription("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"))
    daemon = daemon_of(scene, [a, b])
    pose = ship.wait(2)[-1]
    assert pose.header.frame_id == "map"
    assert (pose.pose.position.x, pose.pose.position.y, pose.pose.position.z) == (20.0, 10.0, -0.0)  # ENU
    assert (pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z, pose.pose.orientation.w) \
        == (0.0, 0.0, 0.0, 1.0)
    ours = [m for m in tf.wait(1) if any(t.child_frame_id == "ship" for t in m.transforms)]
    wait_until(lambda: any(any(t.child_frame_id == "auv" for t in m.transforms) for m in tf.samples),
               what="the AUV's transform")
    transforms = {t.child_frame_id: t for m in tf.samples for t in m.transforms if t.header.frame_id == "map"}
    assert ours and transforms["auv"].transform.translation.x == pytest.approx(0.0, abs=0.1)
    assert transforms["auv"].transform.translation.y == 100.0 and transforms["auv"].transform.translation.z == -30.0
    report = wait_until(lambda: next((m for m in diagnostics.samples
                                      if any(s.name == f"hilgate: {a}" for s in m.status)), None),
                        what="a diagnostic of link a")
    status = {s.name: s for s in report.status}
    mine = status[f"hilgate: {a}"]
    values = {kv.key: kv.value for kv in mine.values}
    assert mine.level == 0 and mine.message == "ready" and mine.hardware_id == "sim"
    assert values["state"] == "up" and values["tx_packets"] == "0" and values["ready"] == "True"
    with Link.open(a, runtime_dir=daemon.runtime) as link:
        link.send(b"hello", dst=2)
        wait_until(lambda: any(kv.key == "tx_packets" and kv.value == "1" for m in diagnostics.samples
                               for s in m.status if s.name == f"hilgate: {a}" for kv in s.values),
                   what="the counter in /diagnostics")
    # nothing was published the scene did not ask for: no link topics (their gli has no ros2)
    assert not any(f"/{a}/" in topic or f"/{b}/" in topic for topic in publications(ns))
    published = daemon.status()["ros2"]
    assert published["domain_id"] > -1 and published["interfaces"] == ["loopback"]
    assert published["published"]["poses"] > 0 and published["failed"] == 0


def test_a_ros2_node_and_a_dccomms_application_talk_through_two_links(daemon_of, dds):
    ns = namespace()
    node_link, app_link = unique("node"), unique("app")
    Frame = message_class("hilgate_msgs/msg/Frame")
    recv = dds(Subscription(f"{ns}/{node_link}/recv", "hilgate_msgs/msg/Frame"))
    ready = dds(Subscription(f"{ns}/{node_link}/ready", "std_msgs/msg/Bool", durability="transient_local"))
    send = dds(Publication(f"{ns}/{node_link}/send", "hilgate_msgs/msg/Frame"))
    daemon = daemon_of(node_and_app_scene(ns, node_link, app_link, 300, 2000), [node_link, app_link])
    assert ready.wait(1)[-1].data is True  # the state a node that starts late gets at once
    application = daemon.peer(app_link, "--send", "1", "--dst", "1", "--receive", "1", "--timeout", "60")
    heard = recv.wait(1)[0]  # the dccomms application's frame reaches the node
    assert (heard.src, heard.dst, bytes(heard.data)) == (2, 1, f"{app_link}#0000".encode()[:10])
    assert heard.model_time > 0.2 and heard.stamp.sec > 1_600_000_000
    wait_until(lambda: send.matched(), what="hilgate's reader of the send topic")
    send.write(Frame(dst=2, data=b"from ROS 2"))  # and the node answers
    events = peer_events(application)
    frames = [e for e in events if e["ev"] == "frame"]
    assert [(f["payload"], f["src"], f["dst"], f["crc_ok"]) for f in frames] == [("from ROS 2", 1, 2, True)]
    wait_until(lambda: len(ready.samples) >= 3, what="BUSY and READY again")  # it went BUSY while sending
    assert [s.data for s in ready.samples][-2:] == [False, True]
    # the type hash of each endpoint hilgate opened, in its USER_DATA, as a Jazzy node reads it
    seen = wait_until(lambda: (lambda p: p if len(p) == 3 else None)(publications(ns)), what="three writers")
    # (hilgate's recv and ready, and this test's own send)
    assert seen[f"rt{ns}/{node_link}/recv"] == ("hilgate_msgs::msg::dds_::Frame_", user_data("hilgate_msgs/msg/Frame"))
    assert seen[f"rt{ns}/{node_link}/ready"] == ("std_msgs::msg::dds_::Bool_", user_data("std_msgs/msg/Bool"))


# -- hostile and broken nodes -------------------------------------------------------------------------


def test_poses_that_are_no_poses_are_counted_and_never_applied(daemon_of, dds):
    ns = namespace()
    link = unique("h")
    scene = ros2_scene(
        ns, f"  rov: {{pose: {{ros2: {{topic: {ns}/rov/pose_in, type: geometry_msgs/msg/PoseStamped, frame_id: odom}}}}}}\n",
        f"  {link}: {{vehicle: rov, address: 1, gli: [socket]}}\n")
    PoseStamped = message_class("geometry_msgs/msg/PoseStamped")
    publication = dds(Publication(f"{ns}/rov/pose_in", "geometry_msgs/msg/PoseStamped"))
    daemon = daemon_of(scene, [link])

    def pose(x, y, z, frame="odom"):
        message = PoseStamped()
        message.header.frame_id = frame
        message.pose.position.x, message.pose.position.y, message.pose.position.z = x, y, z
        message.pose.orientation.w = 1.0
        return message

    wait_until(publication.matched, what="hilgate's reader")
    publication.write(pose(1.0, 2.0, -3.0))
    wait_until(lambda: daemon.vehicle("rov")["position"] == [2.0, 1.0, 3.0], what="the good pose")
    publication.write(pose(math.nan, 0.0, 0.0))
    publication.write(pose(0.0, math.inf, 0.0))
    publication.write(pose(1e300, 0.0, 0.0))
    publication.write(pose(7.0, 7.0, 7.0, frame="map"))  # another frame than the scene's
    # CDR that Cyclone DDS passes (it refuses truncated samples itself) but that is no text: a frame id
    # in Latin-1, as a tool that is not ROS might write it
    latin = pose(0.0, 0.0, 0.0, frame="od").serialize().replace(b"od\x00", b"\xf6d\x00")
    publication.write_raw(latin)
    publication.write_raw(latin)
    publication.write(pose(4.0, 5.0, -6.0))  # and a good one after them all is taken
    wait_until(lambda: daemon.vehicle("rov")["position"] == [5.0, 4.0, 6.0], what="the last good pose")
    source = wait_until(lambda: (lambda s: s if sum(s["refused"].values()) == 6 else None)(
        daemon.status()["ros2"]["poses_in"][0]), what="six refusals")
    assert source["refused"] == {"not_finite": 2, "out_of_range": 1, "frame_id": 1, "decode": 2}
    assert source["messages"] == 6  # the decoded ones: two good, four refused
    assert source["applied"] == 2
    assert daemon.process.poll() is None and "Traceback" not in daemon.output()


def test_frames_a_node_floods_or_breaks_are_counted_by_cause_and_none_is_lost_uncounted(daemon_of, dds):
    ns = namespace()
    node_link, app_link = unique("f"), unique("g")
    Frame = message_class("hilgate_msgs/msg/Frame")
    send = dds(Publication(f"{ns}/{node_link}/send", "hilgate_msgs/msg/Frame"))
    daemon = daemon_of(node_and_app_scene(ns, node_link, app_link, 15, 1000000, ", gli: [socket]"), [node_link, app_link])
    flood = 400
    wait_until(send.matched, what="hilgate's reader")
    send.write(Frame(dst=2, data=bytes(70_000)))   # more than any packet class carries
    send.write(Frame(dst=2, data=bytes(3000)))     # more than this link's packet class carries
    for i in range(flood):                          # far faster than the door lets one writer send
        send.write(Frame(dst=2, data=i.to_bytes(2, "big")))
    total = flood + 2

    def accounted():
        events = daemon.trace_events()
        enq = sum(1 for e in events if e.get("ev") == "enq" and e.get("src") == node_link)
        drops = {}
        for e in events:
            if e.get("ev") == "drop" and e.get("link") == node_link:
                drops[e["cause"]] = drops.get(e["cause"], 0) + e.get("n", 1)
        return (enq, drops) if enq + sum(drops.values()) == total else None

    enq, drops = wait_until(accounted, what="every frame sent or counted")
    assert drops["bad_frame"] == 2 and drops.get("rate", 0) + drops.get("client_queue", 0) > 0
    assert set(drops) <= {"bad_frame", "rate", "client_queue"} and enq >= 64
    assert daemon.process.poll() is None and "Traceback" not in daemon.output()
    assert sum(daemon.link_status(node_link)["drop_causes"].values()) == total - enq


# -- the domain and reloads ----------------------------------------------------------------------------------


def test_domain_from_ros_domain_id_and_reloads_that_add_a_link_or_would_move_the_domain(daemon_of, dds):
    ns = namespace()
    first, second = unique("p"), unique("q")
    base = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  a: {{pose: {{static: [0, 0, 0]}}}}
links:
  {first}: {{vehicle: a, address: 1, gli: [ros2]}}
"""
    section = f"ros2: {{namespace: {ns}}}\n"
    daemon = daemon_of(base + section, [first, second], env={"ROS_DOMAIN_ID": str(DOMAIN)})
    ready = dds(Subscription(f"{ns}/{second}/ready", "std_msgs/msg/Bool", durability="transient_local"))
    assert daemon.status()["ros2"]["domain_id"] == DOMAIN
    daemon.reload(base + f"  {second}: {{vehicle: a, address: 2, gli: [socket, ros2]}}\n" + section)
    assert ready.wait(1)[-1].data is True  # the new link's topics, on the running participant
    moved = base + f"ros2: {{namespace: {ns}, domain_id: {(DOMAIN + 1) % 233}}}\n"
    daemon.scene.write_text(moved)
    reply = daemon.control({"class": "RELOAD"})
    assert reply["ok"] is False and reply["error"].endswith(
        ": ros2: domain_id, interfaces, peers, namespace and links are fixed while the daemon runs (ROS 2 nodes "
        "hold its topics): restart it to change them")
    assert reply["error"].count("ros2:") == 1  # the key once, not "ros2: ros2: …" (issue 39)
    assert daemon.status()["ros2"]["domain_id"] == DOMAIN and daemon.link_status(second)["state"] == "up"


def test_a_refused_reload_names_the_ros2_key_once():
    """The bridge's SceneError puts the key in front of the reason; the reason must not carry it too."""
    from types import SimpleNamespace

    from hilgate.daemon.ros2_bridge import Ros2Bridge
    from hilgate.scene import SceneError
    from hilgate.scene.ros2 import Ros2Spec

    bridge = Ros2Bridge(scheduler=None, router=None, scene_path="lab.yaml")
    bridge.prepare(SimpleNamespace(uses_ros2=True, ros2=Ros2Spec(domain_id=3)))
    bridge.node._participant = object()  # joined: the domain is now fixed (no DDS needed to say so)
    with pytest.raises(SceneError) as refused:
        bridge.prepare(SimpleNamespace(uses_ros2=True, ros2=Ros2Spec(domain_id=4)))
    assert str(refused.value) == ("lab.yaml: ros2: domain_id, interfaces, peers, namespace and links are fixed "
                                  "while the daemon runs (ROS 2 nodes hold its topics): restart it to change them")


def test_a_ros_domain_id_that_is_no_domain_is_refused_in_one_line(tmp_path):
    link = unique("d")
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  a: {{pose: {{static: [0, 0, 0]}}}}
links:
  {link}: {{vehicle: a, gli: [ros2]}}
"""
    daemon = Daemon(tmp_path, scene, [link], env={"ROS_DOMAIN_ID": "999"})
    try:
        assert daemon.process.wait(60) != 0
        errors = [line for line in daemon.output().splitlines() if line.startswith("hilgate: ")]
        assert len(errors) == 1 and errors[0].endswith("ros2: ROS_DOMAIN_ID='999' is not a domain id from 0 to 232")
        assert "Traceback" not in daemon.output()
    finally:
        daemon.close()


def test_diagnostics_of_many_links_go_out_in_chunks_one_turn_each(tmp_path):
    """The publisher on the model's clock (virtual time) and the test's own participant: 40 links make
    three arrays of 16, 16 and 8 statuses, each built in its own turn of the loop."""
    from ros2kit import node
    from hilgate.core.scheduler import VirtualScheduler
    from hilgate.ros2.publish import CHUNK, Publisher
    from hilgate.scene.ros2 import PublishSpec, Ros2Spec, ros_token

    ns = namespace()
    spec = Ros2Spec(namespace=ns, diagnostics=PublishSpec(1.0), poses=PublishSpec(1.0))
    scheduler = VirtualScheduler()
    turns = []

    def link(i):
        def status():
            turns.append(scheduler.now())
            return {"id": f"l{i}", "state": "up", "ready": i % 2 == 0, "tx_packets": i, "rx_packets": 0, "drops": 0,
                    "unread": 0, "fifo_bytes": 0, "drop_causes": {"rate": 1} if i == 3 else {}, "backend": "sim"}
        return status

    vehicles = [lambda i=i: (f"v{i}", (float(i), 0.0, 0.0), None, None, False) for i in range(20)]
    diagnostics = Subscription("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
    poses = Subscription(f"{ns}/v19/pose", "geometry_msgs/msg/PoseStamped")
    publisher = Publisher(node(), scheduler, spec, lambda: vehicles, lambda: [link(i) for i in range(40)], ros_token)
    try:
        wait_until(lambda: publisher.diag_writer.get_publication_matched_status().current_count, what="the match")
        scheduler.run(1.0)
        arrays = [m for m in diagnostics.wait(3) if any(s.name.startswith("hilgate: l") for s in m.status)]
        assert [len(m.status) for m in arrays] == [CHUNK, CHUNK, 40 - 2 * CHUNK]
        assert len(turns) == 40 and scheduler.now() == 1.0
        statuses = {s.name: s for m in arrays for s in m.status}
        assert statuses["hilgate: l1"].level == 1 and statuses["hilgate: l1"].message == "busy"
        assert {kv.key: kv.value for kv in statuses["hilgate: l3"].values}["drops.rate"] == "1"
        assert poses.wait(1)[0].pose.position.y == 19.0  # the 20th vehicle, in the second turn
        assert publisher.status() == {"published": {"poses": 20, "tf": 0, "diagnostics": 3}, "failed": 0, "skipped": 0}
    finally:
        publisher.close()
        diagnostics.close()
        poses.close()
