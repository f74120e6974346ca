"""Pose sources built from a scene's vehicle specs (scripted ones here; live ones join later)."""

from __future__ import annotations

from typing import Any, Callable

from .models.trajectories import Piecewise, PoseSource, Static, path_segments, waypoint_segments
from .scene import PoseSpec


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


BUILDERS: dict[str, Callable[[Any], PoseSource]] = {
    "static": _static,
    "path": _path,
    "waypoints": _waypoints,
}


def build_pose(spec: PoseSpec) -> PoseSource:
    return BUILDERS[spec.kind](spec.params)
