"""Pose sources built from a scene's vehicles: scripted ones, application-driven ones, live ones.

Live vehicles (MAVLink, ArUco) are :class:`~hilgate.sim.live_vehicle.LiveVehicle` entries of the pose board;
what feeds them runs in the daemon (:mod:`hilgate.daemon.live_sources`).  In virtual time nothing feeds them: they
stay at their ``initial`` position (or, without one, nowhere: their modems are heard by nobody).
"""

from __future__ import annotations

from typing import Any, Callable

from ..models.controlled import Controlled
from ..models.trajectories import Piecewise, PoseSource, Static, path_segments, waypoint_segments
from .live_vehicle import LiveVehicle
from ..scene import VehicleSpec


def _static(params: Any) -> PoseSource:
    return Static(params)


def _path(params: Any) -> PoseSource:
    start, legs, loop = params
    segments = path_segments(start, [dict(leg) for leg in legs])
    source = Piecewise(segments, loop=loop)
    return Static(start) if source.static else source


def _waypoints(params: Any) -> PoseSource:
    source = Piecewise(waypoint_segments(params))
    return Static(params[0][1:4]) if source.static else source


def _controlled(params: Any) -> PoseSource:
    start, max_speed = params
    return Controlled(start, max_speed)


BUILDERS: dict[str, Callable[[Any], PoseSource]] = {
    "static": _static,
    "path": _path,
    "waypoints": _waypoints,
    "controlled": _controlled,
}


def build_pose(vehicle: VehicleSpec) -> PoseSource:
    spec = vehicle.pose
    if spec.kind == "live":
        return LiveVehicle(vehicle.name, vehicle.initial, vehicle.stale_after_s, vehicle.stale,
                           vehicle.extrapolate_s, dict(spec.merge))
    return BUILDERS[spec.kind](spec.params)
