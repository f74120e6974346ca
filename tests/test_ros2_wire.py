"""The bytes and type hashes hilgate puts on DDS, held against rosbags' (its ROS 2 Humble and Jazzy type
stores: definitions and CDR written by another project, from ROS's own message files), and pinned where
ROS's generated code states a hash.

The CDR is what a live daemon published, read as the wire carried it (tests/ros2kit.py); the messages
hilgate reads are written by rosbags, byte for byte, and must move a vehicle.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from ros2kit import Publication, Subscription, dds, namespace, ros2_scene, wait_until  # noqa: F401  (dds: a fixture)
from daemon_kit import unique
from hilgate.client import Link
from hilgate.ros2 import messages
from hilgate.ros2.idl import message_class

typesys = pytest.importorskip("rosbags.typesys")
STORES = {"humble": typesys.Stores.ROS2_HUMBLE, "jazzy": typesys.Stores.ROS2_JAZZY}
FRAME_MSG = Path(__file__).resolve().parent.parent / "ros2" / "hilgate_msgs" / "msg" / "Frame.msg"
PUBLISHED = ["geometry_msgs/msg/PoseStamped", "tf2_msgs/msg/TFMessage", "diagnostic_msgs/msg/DiagnosticArray",
             "hilgate_msgs/msg/Frame", "std_msgs/msg/Bool"]
READ = ["nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped"]


def store(name: str):
    """rosbags' type store, with hilgate_msgs registered from the package's own Frame.msg."""
    typestore = typesys.get_typestore(STORES[name])
    typestore.register(typesys.get_types_from_msg(FRAME_MSG.read_text(), "hilgate_msgs/msg/Frame"))
    return typestore


# -- type hashes (REP-2011), no DDS ---------------------------------------------------------------------

@pytest.mark.parametrize("distro", STORES)
def test_every_type_hash_equals_the_one_rosbags_computes_from_its_definitions(distro):
    typestore = store(distro)
    for name in messages.DEFINITIONS:
        assert messages.type_hash(name) == typestore.hash_rihs01(name), name


def test_type_hashes_pinned_where_ros_generated_code_states_them():
    # from rosidl_generator_c's *__description.c of Jazzy's builtin_interfaces, std_msgs, geometry_msgs
    assert messages.type_hash("builtin_interfaces/msg/Time") == \
        "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"
    assert messages.type_hash("std_msgs/msg/Header") == \
        "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"
    assert messages.type_hash("geometry_msgs/msg/Point") == \
        "RIHS01_6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881"


def test_the_package_frame_msg_says_what_hilgate_declares():
    typestore = store("jazzy")
    fields = typestore.fielddefs["hilgate_msgs/msg/Frame"][1]
    assert [name for name, _ in fields] == [f.name for f in messages.fields("hilgate_msgs/msg/Frame")]
    assert messages.user_data("hilgate_msgs/msg/Frame") == f"typehash={typestore.hash_rihs01('hilgate_msgs/msg/Frame')};".encode()
    package = FRAME_MSG.parent.parent
    assert "<name>hilgate_msgs</name>" in (package / "package.xml").read_text()
    assert '"msg/Frame.msg"' in (package / "CMakeLists.txt").read_text()


def test_dds_names_are_mangled_as_ros2_does():
    assert messages.dds_type_name("geometry_msgs/msg/PoseStamped") == "geometry_msgs::msg::dds_::PoseStamped_"
    assert messages.dds_topic("/bluerov/pose") == "rt/bluerov/pose"


# -- CDR, no DDS ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("distro", STORES)
def test_odometry_and_pose_stamped_serialize_as_rosbags_does(distro):
    """The issue's check, with values in every field: 76 B of PoseStamped (frame "map"), 716 B of Odometry."""
    ts = store(distro)
    T = ts.types
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1700000000, nanosec=123456789),
                                      frame_id="map")
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=1.5, y=-2.25, z=-7.0),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.38268343236, w=0.92387953251))
    import numpy

    covariance = numpy.arange(36, dtype=numpy.float64) / 7.0
    twist = T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.5, y=0.0, z=-0.1),
                                         angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.2))
    theirs = {
        "geometry_msgs/msg/PoseStamped": T["geometry_msgs/msg/PoseStamped"](header=header, pose=pose),
        "nav_msgs/msg/Odometry": T["nav_msgs/msg/Odometry"](
            header=header, child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=covariance),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=covariance)),
    }
    Time, Header = message_class("builtin_interfaces/msg/Time"), message_class("std_msgs/msg/Header")
    Point, Quaternion = message_class("geometry_msgs/msg/Point"), message_class("geometry_msgs/msg/Quaternion")
    Pose, Vector3 = message_class("geometry_msgs/msg/Pose"), message_class("geometry_msgs/msg/Vector3")
    ours_header = Header(Time(1700000000, 123456789), "map")
    ours_pose = Pose(Point(1.5, -2.25, -7.0), Quaternion(0.0, 0.0, 0.38268343236, 0.92387953251))
    ours = {
        "geometry_msgs/msg/PoseStamped": message_class("geometry_msgs/msg/PoseStamped")(ours_header, ours_pose),
        "nav_msgs/msg/Odometry": message_class("nav_msgs/msg/Odometry")(
            ours_header, "base_link", message_class("geometry_msgs/msg/PoseWithCovariance")(ours_pose, list(covariance)),
            message_class("geometry_msgs/msg/TwistWithCovariance")(
                message_class("geometry_msgs/msg/Twist")(Vector3(0.5, 0.0, -0.1), Vector3(0.0, 0.0, 0.2)), list(covariance))),
    }
    for name in theirs:
        expected = bytes(ts.serialize_cdr(theirs[name], name))
        assert ours[name].serialize() == expected, name
    assert len(ours["geometry_msgs/msg/PoseStamped"].serialize()) == 76
    assert len(ours["nav_msgs/msg/Odometry"].serialize()) == 716


# -- what a live daemon puts on the wire ------------------------------------------------------------

def test_every_message_hilgate_publishes_is_rosbags_cdr_for_humble_and_jazzy(daemon_of, dds):
    ns = namespace()
    link, other = unique("w"), unique("o")
    scene = ros2_scene(ns, f"""\
  rov: {{pose: {{static: [3, 4, 5]}}}}
  buoy: {{pose: {{static: [0, 0, 0]}}}}
""", f"""\
  {link}: {{vehicle: rov, address: 1, gli: [ros2, socket]}}
  {other}: {{vehicle: buoy, address: 2, gli: [socket]}}
""", '''  publish:
    poses: {rate_hz: 20}
    tf: {rate_hz: 20}
    diagnostics: {rate_hz: 5}
''')
    subscriptions = {
        "geometry_msgs/msg/PoseStamped": dds(Subscription(f"{ns}/rov/pose", "geometry_msgs/msg/PoseStamped")),
        "tf2_msgs/msg/TFMessage": dds(Subscription("/tf", "tf2_msgs/msg/TFMessage")),
        "diagnostic_msgs/msg/DiagnosticArray": dds(Subscription("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")),
        "hilgate_msgs/msg/Frame": dds(Subscription(f"{ns}/{link}/recv", "hilgate_msgs/msg/Frame")),
        "std_msgs/msg/Bool": dds(Subscription(f"{ns}/{link}/ready", "std_msgs/msg/Bool", durability="transient_local")),
    }
    daemon = daemon_of(scene, [link, other])
    with Link.open(other, runtime_dir=daemon.runtime) as sender:
        sender.send(bytes(range(40)), dst=1)
        subscriptions["hilgate_msgs/msg/Frame"].wait(1)
    for name, subscription in subscriptions.items():
        subscription.wait(1)
    stores = {distro: store(distro) for distro in STORES}
    for name, subscription in subscriptions.items():
        for raw, sample in list(zip(subscription.raw, subscription.samples))[:5]:
            sent = message_class(name).serialize(sample)  # what hilgate handed to DDS
            # RTPS carries a payload in 4-byte units: the wire adds zeros to the end, which every
            # reader (rosbags, Fast DDS, Cyclone) leaves unread
            assert raw == sent + bytes(-len(sent) % 4), name
            for distro, ts in stores.items():
                message = ts.deserialize_cdr(raw, name)
                assert bytes(ts.serialize_cdr(message, name)) == sent, (distro, name)
    # and the same messages built in rosbags from the values they should carry
    ts = stores["jazzy"]
    T = ts.types
    pose = subscriptions["geometry_msgs/msg/PoseStamped"].samples[0]
    expected = T["geometry_msgs/msg/PoseStamped"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=pose.header.stamp.sec,
                                                                              nanosec=pose.header.stamp.nanosec),
                                        frame_id="world"),
        pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=4.0, y=3.0, z=-5.0),
                                         orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
    assert bytes(ts.serialize_cdr(expected, "geometry_msgs/msg/PoseStamped")) == \
        subscriptions["geometry_msgs/msg/PoseStamped"].raw[0]  # 76 bytes: no padding
    frame = subscriptions["hilgate_msgs/msg/Frame"].samples[0]
    import numpy

    expected = T["hilgate_msgs/msg/Frame"](
        stamp=T["builtin_interfaces/msg/Time"](sec=frame.stamp.sec, nanosec=frame.stamp.nanosec),
        src=2, dst=1, model_time=frame.model_time, data=numpy.arange(40, dtype=numpy.uint8))
    assert bytes(ts.serialize_cdr(expected, "hilgate_msgs/msg/Frame")) == subscriptions["hilgate_msgs/msg/Frame"].raw[0]
    ready = bytes(ts.serialize_cdr(T["std_msgs/msg/Bool"](data=True), "std_msgs/msg/Bool"))
    assert ready + bytes(3) == subscriptions["std_msgs/msg/Bool"].raw[0]


@pytest.mark.parametrize("type_name", READ)
def test_rosbags_bytes_move_a_vehicle(daemon_of, dds, type_name):
    """A pose serialized by rosbags (Humble's store, then Jazzy's), written to the wire as it is."""
    ns = namespace()
    link = unique("r")
    scene = ros2_scene(ns, f"""\
  rov: {{pose: {{ros2: {{topic: {ns}/rov/pose_in, type: {type_name}, frame: ned, offset: [1, 1, 1]}}}}}}
""", f"""\
  {link}: {{vehicle: rov, address: 1, gli: [socket]}}
""")
    publication = dds(Publication(f"{ns}/rov/pose_in", type_name))
    daemon = daemon_of(scene, [link])
    wait_until(publication.matched, what="hilgate's reader")
    for i, distro in enumerate(STORES):
        ts = store(distro)
        T = ts.types
        header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="odom")
        pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=10.0 + i, y=20.0, z=30.0),
                                           orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        import numpy

        covariance = numpy.zeros(36)
        if type_name == "geometry_msgs/msg/PoseStamped":
            message = T[type_name](header=header, pose=pose)
        elif type_name == "geometry_msgs/msg/PoseWithCovarianceStamped":
            message = T[type_name](header=header, pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=covariance))
        else:
            zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
            message = T[type_name](header=header, child_frame_id="base_link",
                                   pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=covariance),
                                   twist=T["geometry_msgs/msg/TwistWithCovariance"](
                                       twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=covariance))
        publication.write_raw(bytes(ts.serialize_cdr(message, type_name)))
        want = [11.0 + i, 21.0, 31.0]
        wait_until(lambda: daemon.vehicle("rov")["position"] == want, what=f"the pose from rosbags' {distro} bytes")
