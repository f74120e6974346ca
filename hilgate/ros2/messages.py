"""The ROS 2 messages hilgate reads and writes, written once in ROS's own ``.msg`` notation, and their
REP-2011 type description hashes (``RIHS01_…``).

Everything else is derived from :data:`DEFINITIONS`: the Cyclone DDS classes that put the messages on
the wire (:mod:`hilgate.ros2.idl`), the DDS type names (``geometry_msgs::msg::dds_::PoseStamped_``) and
the hash a Jazzy node expects in each endpoint's USER_DATA (``typehash=RIHS01_…;``).  Keeping the
layouts in the notation of the ROS sources lets a reader hold them against ``ros2 interface show``
line by line.  Pure Python, no DDS: the hash is computed here as ``rosidl_generator_type_description``
computes it (the tests check it against rosbags' definitions and hash, independently).

``hilgate_msgs/msg/Frame`` is hilgate's own; its ROS 2 package (``ros2/hilgate_msgs`` in the
repository: ``msg/Frame.msg``, ``package.xml``, ``CMakeLists.txt``) is for labs to build, so their nodes
can ``ros2 topic echo`` and publish frames; the tests check that its ``.msg`` file says the same.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass

__all__ = ["DEFINITIONS", "Field", "fields", "dds_type_name", "type_hash", "type_description",
           "user_data", "dds_topic"]

DEFINITIONS: dict[str, str] = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec",
    "std_msgs/msg/Header": "builtin_interfaces/msg/Time stamp\nstring frame_id",
    "std_msgs/msg/Bool": "bool data",
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/msg/Quaternion": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w",
    "geometry_msgs/msg/Pose": "geometry_msgs/msg/Point position\ngeometry_msgs/msg/Quaternion orientation",
    "geometry_msgs/msg/PoseStamped": "std_msgs/msg/Header header\ngeometry_msgs/msg/Pose pose",
    "geometry_msgs/msg/PoseWithCovariance": "geometry_msgs/msg/Pose pose\nfloat64[36] covariance",
    "geometry_msgs/msg/PoseWithCovarianceStamped":
        "std_msgs/msg/Header header\ngeometry_msgs/msg/PoseWithCovariance pose",
    "geometry_msgs/msg/Twist": "geometry_msgs/msg/Vector3 linear\ngeometry_msgs/msg/Vector3 angular",
    "geometry_msgs/msg/TwistWithCovariance": "geometry_msgs/msg/Twist twist\nfloat64[36] covariance",
    "nav_msgs/msg/Odometry": "std_msgs/msg/Header header\nstring child_frame_id\n"
                             "geometry_msgs/msg/PoseWithCovariance pose\ngeometry_msgs/msg/TwistWithCovariance twist",
    "geometry_msgs/msg/Transform": "geometry_msgs/msg/Vector3 translation\ngeometry_msgs/msg/Quaternion rotation",
    "geometry_msgs/msg/TransformStamped":
        "std_msgs/msg/Header header\nstring child_frame_id\ngeometry_msgs/msg/Transform transform",
    "tf2_msgs/msg/TFMessage": "geometry_msgs/msg/TransformStamped[] transforms",
    "diagnostic_msgs/msg/KeyValue": "string key\nstring value",
    "diagnostic_msgs/msg/DiagnosticStatus": "byte level\nstring name\nstring message\nstring hardware_id\n"
                                            "diagnostic_msgs/msg/KeyValue[] values",
    "diagnostic_msgs/msg/DiagnosticArray": "std_msgs/msg/Header header\ndiagnostic_msgs/msg/DiagnosticStatus[] status",
    # hilgate's own (ros2/hilgate_msgs/msg/Frame.msg): one frame of a link, to it (send) or from it (recv)
    "hilgate_msgs/msg/Frame": "builtin_interfaces/msg/Time stamp\nuint8 src\nuint8 dst\nfloat64 model_time\nuint8[] data",
}

# type_description_interfaces/msg/FieldType: the id of each basic type; an array adds 48, a bounded
# sequence 96, an unbounded one 144 (``char`` is uint8 and ``byte`` octet in ROS 2's IDL)
BASIC_IDS = {"bool": 15, "byte": 16, "char": 3, "float32": 10, "float64": 11, "int8": 2, "uint8": 3,
             "int16": 4, "uint16": 5, "int32": 6, "uint32": 7, "int64": 8, "uint64": 9, "string": 17}
NESTED_ID = 1
ARRAY, BOUNDED, UNBOUNDED = 48, 96, 144
_FIELD = re.compile(r"(?P<type>[A-Za-z][A-Za-z0-9_/]*)(?P<seq>\[(?P<bound><=)?(?P<size>[0-9]*)\])?\s+(?P<name>[a-z][a-z0-9_]*)")


@dataclass(frozen=True)
class Field:
    name: str
    base: str                 # a basic type (``float64``) or a message's full name
    size: int | None = None   # None: not a sequence; 0 with ``bounded`` False: unbounded
    fixed: bool = False       # ``T[N]``: an array of exactly ``size``
    bounded: bool = False     # ``T[<=N]``

    @property
    def nested(self) -> bool:
        return self.base not in BASIC_IDS

    @property
    def sequence(self) -> bool:
        return self.size is not None


def fields(name: str) -> list[Field]:
    """The fields of message ``name`` in order (a ``.msg`` body: ``type name`` per line, ``#`` comments)."""
    result = []
    for line in DEFINITIONS[name].splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        match = _FIELD.fullmatch(line)
        if match is None:
            raise ValueError(f"{name}: cannot read field {line!r}")
        size = None
        if match["seq"]:
            size = int(match["size"] or 0)
        result.append(Field(match["name"], match["type"], size, bool(match["seq"] and match["size"] and not match["bound"]),
                            bool(match["bound"])))
    return result


def dds_type_name(name: str) -> str:
    """``geometry_msgs/msg/PoseStamped`` → ``geometry_msgs::msg::dds_::PoseStamped_`` (ROS 2's DDS mangling)."""
    package, kind, short = name.split("/")
    return f"{package}::{kind}::dds_::{short}_"


def dds_topic(topic: str) -> str:
    """A ROS 2 topic's DDS name: ``/bluerov/odom`` → ``rt/bluerov/odom``."""
    return "rt" + topic if topic.startswith("/") else "rt/" + topic


def _field_type(field: Field) -> dict:
    type_id = NESTED_ID if field.nested else BASIC_IDS[field.base]
    capacity = 0
    if field.sequence:
        if field.fixed:
            type_id, capacity = type_id + ARRAY, field.size
        elif field.bounded:
            type_id, capacity = type_id + BOUNDED, field.size
        else:
            type_id += UNBOUNDED
    return {"type_id": type_id, "capacity": capacity, "string_capacity": 0,
            "nested_type_name": field.base if field.nested else ""}


def _individual(name: str) -> dict:
    return {"type_name": name, "fields": [{"name": f.name, "type": _field_type(f)} for f in fields(name)]}


def type_description(name: str) -> dict:
    """REP-2011's TypeDescription of ``name`` (default values left out, as the hash leaves them out):
    the type and every type it refers to, directly or not, sorted by name."""
    referenced: set[str] = set()
    pending = [f.base for f in fields(name) if f.nested]
    while pending:
        other = pending.pop()
        if other not in referenced:
            referenced.add(other)
            pending.extend(f.base for f in fields(other) if f.nested)
    return {"type_description": _individual(name),
            "referenced_type_descriptions": [_individual(other) for other in sorted(referenced)]}


def type_hash(name: str) -> str:
    """``RIHS01_`` and the SHA-256 of the TypeDescription in JSON, written as rosidl writes it (no
    indentation, ``', '`` and ``': '`` between items, keys in their order)."""
    text = json.dumps(type_description(name), ensure_ascii=True, allow_nan=False, separators=(", ", ": "))
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def user_data(name: str) -> bytes:
    """What a ROS 2 (Jazzy and later) endpoint carries in its USER_DATA QoS: without it a Jazzy node
    warns and shows the type hash as INVALID (data still flows)."""
    return f"typehash={type_hash(name)};".encode("ascii")
