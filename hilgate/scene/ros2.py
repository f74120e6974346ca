"""The ``ros2:`` of a scene: hilgate as a ROS 2 participant (docs/ros2.md), and a vehicle's ``ros2`` pose.

Three uses, each only where the scene asks for it (hilgate publishes nothing it was not asked for):

- a vehicle's ``pose: {ros2: {topic, type}}`` takes its pose from a ROS 2 topic;
- a link's ``gli: [..., ros2]`` opens its topics for ROS 2 nodes (send, recv, ready);
- the section's ``publish:`` lists what hilgate publishes: vehicles' poses, ``/tf``, ``/diagnostics``.

The section itself says how: the DDS domain (else ``ROS_DOMAIN_ID``, else 0), the namespace of the
topics, the interfaces (loopback only unless named), the ROS side's axes.  Any of these needs the
``ros2`` extra (Cyclone DDS); a scene that uses ROS 2 without it is refused in one line saying so.
Nothing here imports Cyclone DDS: the scene is checked where the extra may be missing.
"""

from __future__ import annotations

import importlib.util
import re
from dataclasses import dataclass
from typing import Any

from .checks import Fields, choice, describe, integer, matching, number, one_or_more, text, vector
from .yaml_nodes import Node

__all__ = ["Ros2Spec", "PublishSpec", "ros2_spec", "ros2_pose", "require_extra", "ros_token", "POSE_TYPES",
           "EXTRA_HINT", "MAX_DOMAIN_ID", "check_ros2_names"]

EXTRA_HINT = "needs the ros2 extra (Cyclone DDS): pip install 'hilgate[ros2]'"
MAX_DOMAIN_ID = 232  # the largest domain whose ports fit below 65536 (Cyclone and Fast DDS port maps)
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
RELIABILITY = ("reliable", "best_effort")
ROS2_KEYS = ("domain_id", "namespace", "interfaces", "peers", "frame", "frame_id", "publish", "links")
PUBLISH_KEYS = ("poses", "tf", "diagnostics")
POSE_KEYS = ("topic", "type", "frame", "frame_id", "offset", "reliability")
_NAME = re.compile(r"/?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*")
_INTERFACE = re.compile(r"[A-Za-z0-9_.:%-]{1,64}")
_FRAME_ID = re.compile(r"[A-Za-z0-9_/.-]{1,128}")


@dataclass(frozen=True)
class PublishSpec:
    """One thing hilgate publishes, at ``rate_hz`` (wall clock), with its reliability."""

    rate_hz: float
    reliability: str = "reliable"


@dataclass(frozen=True)
class Ros2Spec:
    domain_id: int | None = None           # None: ROS_DOMAIN_ID of the daemon's environment, else 0
    namespace: str = "/hilgate"
    interfaces: tuple[str, ...] = ()       # (): loopback only
    peers: tuple[str, ...] = ()            # unicast discovery peers besides multicast
    frame: str = "enu"                     # the ROS side's axes (REP-103 ENU/FLU, or NED/FRD)
    frame_id: str = "world"                # header.frame_id of the poses and tf hilgate publishes
    poses: PublishSpec | None = None       # <namespace>/<vehicle>/pose, geometry_msgs/msg/PoseStamped
    tf: PublishSpec | None = None          # /tf: frame_id → each vehicle
    diagnostics: PublishSpec | None = None  # /diagnostics: each link's state and counters
    links_reliability: str = "reliable"    # the links' send, recv topics

    @property
    def participant(self) -> tuple:
        """What the participant is made with: changing any of it needs a restart."""
        return (self.domain_id, self.interfaces, self.peers)


def require_extra(node: Node, path: str) -> None:
    """Refuse, in one line, a scene that needs Cyclone DDS where it is not installed."""
    try:
        found = importlib.util.find_spec("cyclonedds") is not None
    except (ImportError, ValueError):
        found = False
    if not found:
        raise node.error(path, EXTRA_HINT)


def ros_token(name: str) -> str:
    """A scene name (link id, vehicle) as one token of a ROS 2 topic name: letters, digits and single
    underscores, not starting with a digit (``rov-1.a`` → ``rov_1_a``, ``7`` → ``n7``)."""
    token = re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_") or "n"
    return "n" + token if token[0].isdigit() else token


def _topic_name(node: Node, path: str) -> str:
    value = text(node, path)
    if not _NAME.fullmatch(value) or "__" in value:
        raise node.error(path, f"a ROS 2 name is words of letters, digits and single '_' joined by '/', each "
                               f"starting with a letter, not {describe(node)}")
    return value if value.startswith("/") else "/" + value


_frame_id = matching(_FRAME_ID, "a frame id is letters, digits, '_', '/', '.' or '-'")
_interfaces = one_or_more(matching(_INTERFACE, "an interface is a name (eth0) or an address (192.168.2.1)"))


def _publish_item(node: Node, path: str) -> PublishSpec:
    f = Fields(node, path, ("rate_hz", "reliability"))
    return PublishSpec(f.get("rate_hz", number(above=0, maximum=100), 1.0 if path.endswith("diagnostics") else 10.0),
                       f.get("reliability", choice(*RELIABILITY), "reliable"))


def ros2_spec(node: Node) -> Ros2Spec:
    require_extra(node, "ros2")
    f = Fields(node, "ros2", ROS2_KEYS)
    publish: dict[str, Any] = {}
    if f.child("publish") is not None:
        pf = Fields(f.child("publish"), "ros2.publish", PUBLISH_KEYS)
        publish = {key: pf.get(key, _publish_item) for key in PUBLISH_KEYS if key in pf}
    links_reliability = "reliable"
    if f.child("links") is not None:
        lf = Fields(f.child("links"), "ros2.links", ("reliability",))
        links_reliability = lf.get("reliability", choice(*RELIABILITY), "reliable")
    return Ros2Spec(
        domain_id=f.get("domain_id", integer(0, MAX_DOMAIN_ID), None),
        namespace=f.get("namespace", _topic_name, "/hilgate"),
        interfaces=f.get("interfaces", _interfaces, ()),
        peers=f.get("peers", _interfaces, ()),
        frame=f.get("frame", choice("enu", "ned"), "enu"),
        frame_id=f.get("frame_id", _frame_id, "world"),
        links_reliability=links_reliability,
        **publish,
    )


def ros2_pose(node: Node, path: str) -> Any:
    """A vehicle's ``ros2:`` pose source: ``topic`` and ``type`` (Odometry, PoseStamped,
    PoseWithCovarianceStamped); ``frame`` (enu or ned: default the section's); ``frame_id`` (only
    messages stamped in this frame; default any); ``offset`` (where the ROS frame's origin is in the
    scene, scene axes); ``reliability`` (the reader's; a best-effort one hears every writer)."""
    require_extra(node, path)
    f = Fields(node, path, POSE_KEYS)
    return (("topic", f.get("topic", _topic_name)), ("type", f.get("type", choice(*POSE_TYPES))),
            ("frame", f.get("frame", choice("enu", "ned"), None)), ("frame_id", f.get("frame_id", _frame_id, None)),
            ("offset", f.get("offset", vector(), (0.0, 0.0, 0.0))),
            ("reliability", f.get("reliability", choice(*RELIABILITY), "reliable")))


def check_ros2_names(links: dict[str, Any], vehicles: dict[str, Any], node: Node) -> None:
    """Two links (or two vehicles) whose names make the same topic token are refused: their topics
    would be one.  Links on ROS 2 need the extra too (their ``gli`` names it)."""
    for kind, names in (("links", [l.id for l in links.values() if "ros2" in l.gli]), ("vehicles", list(vehicles))):
        seen: dict[str, str] = {}
        for name in names:
            token = ros_token(name)
            if token in seen:
                raise node.error(kind, f"{seen[token]!r} and {name!r} make the same ROS 2 topic name {token!r}: "
                                       "rename one")
            seen[token] = name
