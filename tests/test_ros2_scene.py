"""The scene's ROS 2 parts (``ros2:``, a ``ros2`` pose, ``gli: [ros2]``), the axes between ROS 2 and the
scene, and hilgate without the ros2 extra: a scene that asks for ROS 2 is refused in one line."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from hilgate.ros2 import frames
from hilgate.scene import SceneError, load_scene_text
from hilgate.scene.ros2 import EXTRA_HINT, ros_token

BASE = "channels: {ac: {speed_mps: 1500}}\n"


def scene(vehicles: str = "  a: {pose: {static: [0, 0, 0]}}\n", links: str = "  l1: {vehicle: a}\n", extra: str = ""):
    return f"{BASE}vehicles:\n{vehicles}links:\n{links}{extra}"


def test_a_ros2_section_pose_and_links_are_read():
    loaded = load_scene_text(scene(
        vehicles="  rov:\n    pose: {ros2: {topic: /bluerov/odom, type: nav_msgs/msg/Odometry, frame: ned, "
                 "offset: [1, 2, 3], reliability: best_effort}}\n",
        links="  l1: {vehicle: rov, gli: [mq, ros2]}\n  l2: {vehicle: rov}\n",
        extra="ros2:\n  domain_id: 42\n  namespace: lab/hil\n  interfaces: [eth0, 10.0.0.2]\n"
              "  publish: {poses: {rate_hz: 5}, diagnostics: {}}\n"))
    assert loaded.uses_ros2
    spec = loaded.ros2
    assert (spec.domain_id, spec.namespace, spec.interfaces, spec.frame) == (42, "/lab/hil", ("eth0", "10.0.0.2"), "enu")
    assert spec.poses.rate_hz == 5 and spec.diagnostics.rate_hz == 1.0 and spec.tf is None
    assert loaded.links["l1"].gli == ("mq", "ros2") and loaded.links["l2"].gli == ("mq", "socket")
    (kind, params), = loaded.vehicles["rov"].pose.params
    assert kind == "ros2" and dict(params) == {"topic": "/bluerov/odom", "type": "nav_msgs/msg/Odometry", "frame": "ned",
                                               "frame_id": None, "offset": (1.0, 2.0, 3.0), "reliability": "best_effort"}
    assert not load_scene_text(scene()).uses_ros2


def test_a_ros2_pose_merges_with_mavlink():
    loaded = load_scene_text(scene(vehicles="  rov:\n    pose:\n      ros2: {topic: /odom, type: geometry_msgs/msg/PoseStamped}\n"
                                            "      mavlink: {url: 'udpin:127.0.0.1:14550'}\n"
                                            "      merge: {x: ros2, y: ros2, z: mavlink}\n", links="  l1: {vehicle: rov}\n"))
    assert loaded.vehicles["rov"].pose.merge == (("x", "ros2"), ("y", "ros2"), ("z", "mavlink"))


@pytest.mark.parametrize("text, message", [
    (scene(extra="ros2: {domain_id: 233}\n"), "ros2.domain_id"),
    (scene(extra="ros2: {namespace: 'a b'}\n"), "a ROS 2 name"),
    (scene(extra="ros2: {namespace: /a__b}\n"), "a ROS 2 name"),
    (scene(extra="ros2: {interfaces: ['eth0\"/><x']}\n"), "an interface is"),
    (scene(extra="ros2: {publish: {pose: {}}}\n"), "did you mean 'poses'"),
    (scene(extra="ros2: {publish: {tf: {rate_hz: 0}}}\n"), "ros2.publish.tf.rate_hz"),
    (scene(vehicles="  a: {pose: {ros2: {topic: /x, type: sensor_msgs/msg/Imu}}}\n"), "vehicles.a.pose.ros2.type"),
    (scene(vehicles="  a: {pose: {ros2: {topic: '/x/1y', type: nav_msgs/msg/Odometry}}}\n"), "a ROS 2 name"),
    (scene(vehicles="  a: {pose: {ros2: {type: nav_msgs/msg/Odometry}}}\n"), "missing required key 'topic'"),
    (scene(links="  l-1: {vehicle: a, gli: [ros2]}\n  l.1: {vehicle: a, gli: [ros2]}\n"), "same ROS 2 topic name 'l_1'"),
    (scene(links="  l1: {vehicle: a, gli: [ros3]}\n"), "links.l1.gli[0]"),
])
def test_scene_errors_name_the_key(text, message):
    with pytest.raises(SceneError, match=message.replace("[", r"\[").replace("]", r"\]")) as error:
        load_scene_text(text)
    assert "\n" not in str(error.value)


def test_link_and_vehicle_names_become_ros_names():
    assert [ros_token(n) for n in ("rov-1.a", "7", "a__b", "_x_")] == ["rov_1_a", "n7", "a_b", "x"]


BLOCK = """
import sys
class NoCyclone:
    def find_spec(self, name, path=None, target=None):
        if name == "cyclonedds" or name.startswith("cyclonedds."):
            raise ModuleNotFoundError(f"No module named {name!r}")
sys.meta_path.insert(0, NoCyclone())
for name in [m for m in sys.modules if m.startswith("cyclonedds")]:
    del sys.modules[name]
from hilgate.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("uses", ["section", "pose", "link"])
def test_without_the_extra_a_scene_with_ros2_is_refused_in_one_line_naming_it(tmp_path, uses):
    texts = {"section": scene(extra="ros2: {}\n"),
             "pose": scene(vehicles="  a: {pose: {ros2: {topic: /odom, type: nav_msgs/msg/Odometry}}}\n"),
             "link": scene(links="  l1: {vehicle: a, gli: [socket, ros2]}\n")}
    path = tmp_path / "scene.yaml"
    path.write_text(texts[uses])
    for command in (["check", str(path)], ["run", str(path), "--runtime-dir", str(tmp_path / "rt")]):
        result = subprocess.run([sys.executable, "-c", BLOCK, *command], capture_output=True, text=True, timeout=120)
        lines = result.stderr.strip().splitlines()
        assert result.returncode != 0 and len(lines) == 1, result.stderr
        assert EXTRA_HINT in lines[0] and "pip install 'hilgate[ros2]'" in lines[0]
    path.write_text(scene())  # and without ros2 it runs as before
    result = subprocess.run([sys.executable, "-c", BLOCK, "check", str(path)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


# -- axes -----------------------------------------------------------------------------------------------


def test_positions_cross_between_enu_and_ned():
    assert frames.position_to_scene((1.0, 2.0, 3.0), "enu") == (2.0, 1.0, -3.0)
    assert frames.position_to_scene((1.0, 2.0, 3.0), "ned") == (1.0, 2.0, 3.0)
    assert frames.position_from_scene(frames.position_to_scene((1.0, 2.0, 3.0), "enu"), "enu") == (1.0, 2.0, 3.0)


def test_orientations_cross_between_enu_flu_and_ned_frd():
    # a vehicle facing east: yaw 0 in ENU, 90° in NED; facing north: 90° in ENU, 0 in NED
    east = (0.0, 0.0, 0.0, 1.0)
    north = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
    assert frames.orientation_to_scene(east, "enu") == pytest.approx((0.0, 0.0, math.pi / 2))
    assert frames.orientation_to_scene(north, "enu") == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # nose up 10°: a pitch of -10° about FLU's y (left), +10° about FRD's y (right); facing east
    nose_up = frames.quaternion_from_rpy((0.0, -math.radians(10), 0.0))
    roll, pitch, yaw = frames.orientation_to_scene(nose_up, "enu")
    assert (roll, pitch) == pytest.approx((0.0, math.radians(10))) and yaw == pytest.approx(math.pi / 2)
    for rpy in [(0.1, -0.2, 1.3), (-0.7, 0.4, -2.9), (0.0, 0.0, 0.0)]:
        for frame in frames.FRAMES:
            assert frames.orientation_to_scene(frames.orientation_from_scene(rpy, frame), frame) == pytest.approx(rpy)
    assert frames.orientation_to_scene(frames.quaternion_from_rpy((0.1, -0.2, 1.3)), "ned") == pytest.approx((0.1, -0.2, 1.3))


def test_a_twist_in_the_body_frame_becomes_the_worlds_velocity():
    north = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))  # ENU: facing north
    assert frames.rotate(north, (2.0, 0.0, 0.0)) == pytest.approx((0.0, 2.0, 0.0))  # forward = north
    assert frames.position_to_scene(frames.rotate(north, (2.0, 0.0, 0.0)), "enu") == pytest.approx((2.0, 0.0, 0.0))


def test_cyclone_talks_on_loopback_unless_interfaces_are_named():
    from hilgate.ros2.participant import config_xml

    loopback = config_xml()
    assert '<NetworkInterface address="127.0.0.1"/>' in loopback and "<AllowMulticast>false</AllowMulticast>" in loopback
    assert '<Peer address="127.0.0.1"/>' in loopback and "<ParticipantIndex>auto</ParticipantIndex>" in loopback
    named = config_xml(("eth0", "192.168.2.1"), ("10.0.0.9",))
    assert '<NetworkInterface name="eth0"/><NetworkInterface address="192.168.2.1"/>' in named
    assert "127.0.0.1" not in named and "AllowMulticast" not in named and '<Peer address="10.0.0.9"/>' in named
    assert "<MaxSampleSize>1048576B</MaxSampleSize>" in named
    # (the scene refuses such names; the XML is escaped all the same)
    assert '<NetworkInterface name="a&lt;&quot;\'b"/>' in config_xml(("a<\"'b",))


def test_the_example_of_docs_ros2_md_loads():
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parent.parent / "docs" / "ros2.md").read_text()
    example = re.search(r"```yaml\n(.*?)```", page, re.S).group(1)
    loaded = load_scene_text(BASE + example)
    assert loaded.ros2.domain_id is None and loaded.ros2.poses.rate_hz == 10 and loaded.links["rov"].gli == ("ros2",)
    assert dict(loaded.vehicles["bluerov"].pose.params[0][1])["frame_id"] == "odom"
