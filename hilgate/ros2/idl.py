"""Cyclone DDS classes for the messages of :mod:`hilgate.ros2.messages`, built from their definitions.

Each message becomes an ``IdlStruct`` dataclass named as ROS 2 names it on DDS
(``geometry_msgs::msg::dds_::PoseStamped_``), whose CDR (little-endian, XCDR1, as every ROS 2 RMW
writes it) is byte for byte what a ROS 2 node writes: the tests hold it against rosbags' serializer
for the Humble and Jazzy type stores.  Built from the one set of definitions, so the wire layout and
the type hash cannot drift apart.
"""

from __future__ import annotations

import dataclasses
import types as pytypes
from typing import Any

from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t

from .messages import DEFINITIONS, Field, dds_type_name, fields

__all__ = ["message_class", "CLASSES"]

_BASIC: dict[str, Any] = {"bool": bool, "byte": t.byte, "char": t.uint8, "float32": t.float32, "float64": t.float64,
                          "int8": t.int8, "uint8": t.uint8, "int16": t.int16, "uint16": t.uint16, "int32": t.int32,
                          "uint32": t.uint32, "int64": t.int64, "uint64": t.uint64, "string": str}
_ZERO: dict[str, Any] = {"bool": False, "string": "", "float32": 0.0, "float64": 0.0}

CLASSES: dict[str, type] = {}


def _annotation(field: Field) -> Any:
    element = message_class(field.base) if field.nested else _BASIC[field.base]
    if not field.sequence:
        return element
    if field.fixed:
        return t.array[element, field.size]
    return t.sequence[element, field.size] if field.bounded else t.sequence[element]


def _default(field: Field) -> Any:
    if field.sequence:
        if field.fixed and not field.nested:
            zero = _ZERO.get(field.base, 0)
            return dataclasses.field(default_factory=lambda: [zero] * field.size)
        return dataclasses.field(default_factory=list)
    if field.nested:
        return dataclasses.field(default_factory=message_class(field.base))
    return _ZERO.get(field.base, 0)


def message_class(name: str) -> type:
    """The class of message ``name`` (built once)."""
    cls = CLASSES.get(name)
    if cls is None:
        members = fields(name)
        body = {"__annotations__": {f.name: _annotation(f) for f in members},
                **{f.name: _default(f) for f in members}, "__module__": __name__}
        short = name.rsplit("/", 1)[1]
        cls = pytypes.new_class(short, (IdlStruct,), {"typename": dds_type_name(name)},
                                lambda namespace: namespace.update(body))
        cls = CLASSES[name] = dataclasses.dataclass(cls)
    return cls


for _name in DEFINITIONS:
    message_class(_name)
