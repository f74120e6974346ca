"""The scene keys of the built-in live pose sources a vehicle's ``pose:`` may name (rows of
:mod:`hilgate.scene.pose_table`): ``mavlink`` (a vehicle's autopilot) and ``aruco`` (a marker a camera
of the scene sees); ``ros2`` is read in :mod:`hilgate.scene.ros2` with the rest of the ROS 2 section."""

from __future__ import annotations

from typing import Any

from .checks import Fields, integer, join_path, mapping, number, text, vector
from .yaml_nodes import Node

__all__ = ["mavlink_pose", "aruco_pose"]


def mavlink_pose(node: Node, path: str) -> Any:
    f = Fields(node, path, ("url", "system_id", "origin", "message_rates", "heartbeat"))
    url = f.get("url", text)
    system_id = f.get("system_id", integer(1, 255), None)
    origin = f.get("origin", vector(3), None)  # latitude, longitude (degrees), altitude (m)
    rates: tuple = ()
    rates_node = f.child("message_rates")
    if rates_node is not None:
        rates = tuple((name, number(above=0, maximum=1000)(value, join_path(f.sub("message_rates"), name)))
                      for name, value in mapping(rates_node, f.sub("message_rates")).items())
    # hilgate sends a vehicle nothing the scene did not ask for, and never as its ground station
    # (drivers/mavlink_identity.py says why): heartbeat: false (default) | true | {system_id, component_id, rate_hz}
    from ..drivers import mavlink_identity as ident

    hb_node, hb_path = f.child("heartbeat"), f.sub("heartbeat")
    heartbeat = None
    if hb_node is not None and not hb_node.is_map and not isinstance(hb_node.value, bool):
        raise hb_node.error(hb_path, "must be true, false or {system_id: N, component_id: M, rate_hz: R}")
    if hb_node is not None and (hb_node.is_map or hb_node.value):
        own, component, rate = system_id, ident.DEFAULT_COMPONENT_ID, ident.DEFAULT_HEARTBEAT_HZ  # as a companion's
        where = {"system_id": (f.child("system_id"), f.sub("system_id")), "component_id": (hb_node, hb_path)}
        if hb_node.is_map:
            hf = Fields(hb_node, hb_path, ("system_id", "component_id", "rate_hz"))
            own = hf.get("system_id", integer(1, 255), own)
            component = hf.get("component_id", integer(1, 255), component)
            rate = hf.get("rate_hz", number(above=0, maximum=10), rate)
            where.update({key: (hf.child(key), hf.sub(key)) for key in ("system_id", "component_id") if key in hf})
        if own is None:
            raise hb_node.error(hb_path, "needs a system id to send as: give the vehicle's system_id (hilgate then "
                                "sends as its companion computer does) or heartbeat: {system_id: N}")
        for key, problem in (("system_id", ident.system_problem(own)),
                             ("component_id", ident.component_problem(component))):
            if problem is not None:
                raise where[key][0].error(where[key][1], problem)
        heartbeat = (("system_id", own), ("component_id", component), ("rate_hz", rate))
    return (("url", url), ("system_id", system_id), ("origin", origin), ("message_rates", rates),
            ("heartbeat", heartbeat))


def aruco_pose(node: Node, path: str) -> Any:
    f = Fields(node, path, ("camera", "marker", "offset"))
    camera = f.get("camera", text)
    marker = f.get("marker", integer(0, 100_000), None)
    offset = f.get("offset", vector(), (0.0, 0.0, 0.0))
    return (("camera", camera), ("marker", marker), ("offset", offset))
