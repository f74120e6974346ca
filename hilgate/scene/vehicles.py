"""Vehicles and their pose sources, and the cameras that an ``aruco`` pose source looks through.

A vehicle's ``pose:`` is one scripted source (static, path, waypoints, controlled) or one or more
live ones (mavlink, aruco, ros2) merged axis by axis; :data:`POSE_KINDS` maps each source's key to the
checker of its parameters.  The checked parameters are hashable tuples, so a reload can tell a
changed pose from an unchanged one.
"""

from __future__ import annotations

import math
import os
import re
from typing import Any, Callable

from .checks import (
    Fields, boolean, choice, describe, integer, items, join_path, mapping, number, path_value, text,
    unknown_key_message, vector,
)
from .hosts import host_name
from .pose_table import POSE_SOURCES, check_live
from .specs import CameraSpec, PoseSpec, VehicleSpec
from .yaml_nodes import MAX_FILE_BYTES, Node, SceneError, read_limited

__all__ = ["VEHICLE_KEYS", "CAMERA_KEYS", "LIVE_KINDS", "POSE_KINDS", "vehicle_spec", "camera_spec",
           "check_camera_references", "unknown_pose"]

VEHICLE_KEYS = ("pose", "stale_after_s", "stale", "extrapolate_s", "initial", "feedback", "host")
LIVE_KINDS = tuple(POSE_SOURCES)  # (mavlink, aruco, ros2 and any an installed package adds)
CAMERA_KEYS = ("source", "calibration", "dictionary", "marker_length_m", "fixed", "onboard", "map", "fps", "host")


def _static_pose(node: Node, path: str) -> Any:
    return vector()(node, path)


def _leg(node: Node, path: str) -> dict[str, Any]:
    f = Fields(node, path, ("hold_s", "to", "speed_mps", "duration_s"))
    if "hold_s" in f:
        if any(k in f for k in ("to", "speed_mps", "duration_s")):
            raise f.error("a leg is either {hold_s} or {to, speed_mps} or {to, duration_s}")
        return {"hold_s": f.get("hold_s", number(0))}
    to = f.get("to", vector())
    if ("speed_mps" in f) == ("duration_s" in f):
        raise f.error("a leg with 'to' needs exactly one of speed_mps or duration_s")
    if "speed_mps" in f:
        return {"to": to, "speed_mps": f.get("speed_mps", number(above=0))}
    return {"to": to, "duration_s": f.get("duration_s", number(0))}


def _path_pose(node: Node, path: str) -> Any:
    f = Fields(node, path, ("start", "legs", "loop"))
    start = f.get("start", vector())
    legs_node = f.child("legs")
    legs = [] if legs_node is None else [_leg(n, join_path(f.sub("legs"), i)) for i, n in enumerate(items(legs_node, f.sub("legs")))]
    loop = f.get("loop", boolean, False)
    if loop:
        from ..models.trajectories import path_segments

        segments = path_segments(start, legs)
        if segments[-1].t1 <= 0:
            raise f.error("a looping path needs legs that take time")
        end = segments[-1].p1
        if math.dist(end, start) > 1e-6:
            raise f.error(f"a looping path must end where it starts {list(start)}, it ends at {list(end)}")
    return (start, tuple(tuple(sorted(leg.items())) for leg in legs), loop)


def _waypoints_pose(node: Node, path: str) -> Any:
    rows = []
    previous = -math.inf
    for i, row in enumerate(items(node, path)):
        values = vector(4)(row, join_path(path, i))
        if values[0] <= previous:
            raise row.error(join_path(path, i), f"times must increase: {values[0]:g} after {previous:g}")
        previous = values[0]
        rows.append(values)
    if not rows:
        raise node.error(path, "needs at least one [t, x, y, z] row")
    return tuple(rows)


def _controlled_pose(node: Node, path: str) -> Any:
    f = Fields(node, path, ("start", "max_speed_mps"))
    return (f.get("start", vector()), f.get("max_speed_mps", number(above=0)))


POSE_KINDS: dict[str, Callable[[Node, str], Any]] = {
    "static": _static_pose,
    "path": _path_pose,
    "waypoints": _waypoints_pose,
    "controlled": _controlled_pose,
    **{kind: (lambda node, path, kind=kind: check_live(kind, node, path)) for kind in POSE_SOURCES},
}
"""Every key a vehicle's ``pose:`` may have: the scripted sources, then the live ones of the pose-source
table (:mod:`hilgate.scene.pose_table`)."""


def vehicle_spec(name: str, node: Node, path: str) -> VehicleSpec:
    f = Fields(node, path, VEHICLE_KEYS)
    pose_node = f.child("pose")
    if pose_node is None:
        raise f.error("missing required key 'pose'")
    pose_path = f.sub("pose")
    kinds = dict(mapping(pose_node, pose_path))
    merge_node = kinds.pop("merge", None)
    for kind, params_node in kinds.items():
        if kind not in POSE_KINDS:
            raise params_node.error(join_path(pose_path, kind), unknown_pose(kind))
    if not kinds:
        raise pose_node.error(pose_path, f"give a pose source: {', '.join(POSE_KINDS)}")
    live = [k for k in kinds if k in LIVE_KINDS]
    if len(kinds) > 1 and len(live) != len(kinds):
        raise pose_node.error(pose_path, f"only live sources ({', '.join(LIVE_KINDS)}) can be combined, with merge")
    if len(kinds) > 1 and merge_node is None:
        raise pose_node.error(pose_path, "several sources need 'merge' (e.g. {x: aruco, y: aruco, z: mavlink})")
    merge: tuple = ()
    if merge_node is not None:
        mf = Fields(merge_node, join_path(pose_path, "merge"), ("x", "y", "z"))
        merge = tuple((axis, mf.get(axis, choice(*live))) for axis in ("x", "y", "z") if axis in mf)
    if live:
        sources = tuple((kind, POSE_KINDS[kind](kinds[kind], join_path(pose_path, kind))) for kind in kinds)
        pose = PoseSpec("live", sources, merge)
    else:
        (kind, params_node), = kinds.items()
        pose = PoseSpec(kind, POSE_KINDS[kind](params_node, join_path(pose_path, kind)))
    if not live:
        for key in ("stale_after_s", "stale", "extrapolate_s", "initial"):
            if key in f:
                raise f.child(key).error(f.sub(key), f"only for vehicles with a live pose ({', '.join(LIVE_KINDS)})")
    feedback = _feedback(f)
    return VehicleSpec(
        name, pose, node.line,
        stale_after_s=f.get("stale_after_s", number(above=0), 2.0),
        stale=f.get("stale", choice("hold", "drop"), "hold"),
        extrapolate_s=f.get("extrapolate_s", number(0), 0.0),
        initial=f.get("initial", vector(), None),
        feedback=feedback,
        host=f.get("host", host_name, None),
    )


def _feedback(f: Fields) -> tuple:
    """A vehicle's ``feedback:`` (its measured pose sent back to its autopilot over MAVLink); () without."""
    feedback: tuple = ()
    if "feedback" in f:
        ff = Fields(f.child("feedback"), f.sub("feedback"), ("url", "message", "rate_hz", "origin", "system_id"))
        message = ff.get("message", choice("vision_position_estimate", "gps_input"), "vision_position_estimate")
        origin = ff.get("origin", vector(3), None)
        if message == "gps_input" and origin is None:
            raise ff.error("gps_input needs origin: [latitude, longitude, altitude]")
        feedback = (("url", ff.get("url", text)), ("message", message), ("rate_hz", ff.get("rate_hz", number(above=0,
                    maximum=100), 4.0)), ("origin", origin), ("system_id", ff.get("system_id", integer(1, 255), 1)))
    return feedback


def _placement(node: Node, path: str) -> tuple:
    f = Fields(node, path, ("position", "rpy_deg"))
    return (f.get("position", vector()), f.get("rpy_deg", vector(), (0.0, 0.0, 0.0)))


def camera_spec(name: str, node: Node, path: str, vehicles: dict[str, VehicleSpec]) -> CameraSpec:
    f = Fields(node, path, CAMERA_KEYS)
    source_node = f.child("source")
    if source_node is None:
        raise f.error("missing required key 'source' (a device index, a video file or a stream URL)")
    source = _camera_source(source_node, f.sub("source"))
    from ..drivers.aruco import DICTIONARIES

    dictionary = f.get("dictionary", choice(*DICTIONARIES), "DICT_4X4_50")
    if ("fixed" in f) == ("onboard" in f):
        raise f.error("give exactly one of fixed (the camera's place in the tank) or onboard (on a vehicle)")
    fixed = onboard = None
    markers: tuple = ()
    if "fixed" in f:
        fixed = f.get("fixed", _placement)
        if "map" in f:
            raise f.child("map").error(f.sub("map"), "a map of markers is for an onboard camera")
    else:
        of = Fields(f.child("onboard"), f.sub("onboard"), ("vehicle", "position", "rpy_deg"))
        vehicle = of.get("vehicle", text)
        if vehicle not in vehicles:
            raise of.child("vehicle").error(of.sub("vehicle"), f"no vehicle {vehicle!r}")
        onboard = (vehicle, of.get("position", vector(), (0.0, 0.0, 0.0)), of.get("rpy_deg", vector(), (0.0, 0.0, 0.0)))
        map_node = f.child("map")
        if map_node is None:
            raise f.error("an onboard camera needs a map of markers fixed in the tank")
        entries = []
        for marker_id, marker_node in mapping(map_node, f.sub("map")).items():
            where = join_path(f.sub("map"), marker_id)
            if not re.fullmatch(r"[0-9]{1,9}", marker_id):
                raise marker_node.error(where, "map keys are marker ids (whole numbers)")
            entries.append((int(marker_id), *_placement(marker_node, where)))
        markers = tuple(entries)
    return CameraSpec(name, source, f.get("calibration", _calibration), dictionary, f.get("marker_length_m", number(above=0)),
                      fixed, onboard, markers, f.get("fps", number(above=0), None), f.get("host", host_name, None))


def _camera_source(node: Node, path: str) -> int | str:
    """A device index, a stream URL or a GStreamer pipeline as written; a video file relative to the scene."""
    source = node.value
    if isinstance(source, bool) or not isinstance(source, (int, str)) or source == "":
        raise node.error(path, f"must be a device index or a text, not {describe(node)}")
    if isinstance(source, str) and "://" not in source and not re.search(r"[\s!]", source) and not source.isdigit():
        return path_value(node, path)
    return source


def _calibration(node: Node, path: str) -> str:
    """The camera's calibration file, relative to the scene, read now by the camera driver's own
    reader so that a missing or broken one fails ``hilgate check`` (not the daemon, later)."""
    file = path_value(node, path)
    if not os.path.lexists(file):
        raise node.error(path, f"calibration file {file} does not exist")
    try:
        read_limited(file, MAX_FILE_BYTES, "the calibration file")  # a regular, readable, small file
    except SceneError as exc:
        raise node.error(path, f"{file}: {exc.message}") from None
    from ..drivers.aruco import CameraError, load_calibration

    try:
        load_calibration(file)
    except CameraError as exc:
        raise node.error(path, str(exc)) from None
    return file


def unknown_pose(kind: str) -> str:
    return unknown_key_message(kind, list(POSE_KINDS)).replace("unknown key", "unknown pose source")


def check_camera_references(vehicles: dict[str, VehicleSpec], cameras: dict[str, CameraSpec],
                            vehicles_node: Node) -> None:
    """An ``aruco`` pose names a camera of the scene; a fixed camera needs the vehicle's marker id, an
    onboard one must ride on the vehicle it locates (checked once both sections are read)."""
    for vname, vehicle in vehicles.items():
        for kind, params in (vehicle.pose.params if vehicle.pose.kind == "live" else ()):
            if kind != "aruco":
                continue
            options = dict(params)
            where = join_path(join_path(join_path("vehicles", vname), "pose"), "aruco")
            camera = cameras.get(options["camera"])
            if camera is None:
                raise vehicles_node.value[vname].error(where, f"no camera {options['camera']!r} under cameras:")
            if camera.fixed is not None and options["marker"] is None:
                raise vehicles_node.value[vname].error(where, "a fixed camera needs the vehicle's marker id")
            if camera.onboard is not None and camera.onboard[0] != vname:
                raise vehicles_node.value[vname].error(where, f"camera {camera.name!r} is on {camera.onboard[0]!r}")
