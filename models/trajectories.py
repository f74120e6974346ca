"""Scripted vehicle motion: static points, legged paths and timed waypoints.

Every pose source (these scripted ones here, and the live MAVLink/ArUco/controlled sources of the
daemon) answers the same question, "where is this vehicle at time t?", through :class:`PoseSource`.
The medium asks it once per transmission and receiver, so a scripted source must be cheap: segments
are precomputed and looked up by bisection.  ``static`` lets the medium cache distances between
vehicles that never move, which is what keeps large static scenarios fast.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from typing import Protocol, Sequence

Vec3 = tuple[float, float, float]

__all__ = ["Vec3", "PoseSource", "Computed", "Static", "Segment", "Piecewise", "path_segments", "waypoint_segments"]


class PoseSource(Protocol):
    """Where a vehicle is. ``position`` returns None when the pose is unknown (a stale live source
    with the ``drop`` policy): the vehicle's modems then hear nothing and are heard by nobody.

    Every source (scripted here, ``models.controlled``, the daemon's live vehicles, a new one such as a
    ROS 2 subscriber) declares all of it; what it cannot tell has a stated "don't know" value."""

    static: bool
    """It never moves: the medium computes its distances once."""
    max_speed_mps: float
    """No faster than this between two topology changes; ``math.inf`` when nothing is promised (the
    medium's moving grid then never leaves it out)."""
    attitude: tuple[float, float, float] | None
    """Roll, pitch, yaw (rad) when the source knows them (sent back to an autopilot), else None."""

    def position(self, t: float) -> Vec3 | None: ...

    def age(self, t: float) -> float | None:
        """Seconds since the source last heard of the vehicle (0 for a scripted one; None: never)."""

    def stale(self, t: float) -> bool:
        """Whether the pose is older than the source trusts (a live one; never a scripted one)."""


class Computed:
    """A pose the model computes itself (scripted in the scene, or steered by an application,
    ``models.controlled``): always known and never stale, with no attitude."""

    attitude = None

    def age(self, t: float) -> float:
        return 0.0

    def stale(self, t: float) -> bool:
        return False


class Static(Computed):
    static = True
    max_speed_mps = 0.0

    def __init__(self, position: Sequence[float]):
        self._position: Vec3 = (float(position[0]), float(position[1]), float(position[2]))

    def position(self, t: float) -> Vec3:
        return self._position

    def __repr__(self) -> str:
        return f"Static({self._position})"


@dataclass(frozen=True)
class Segment:
    """Straight-line motion from ``p0`` at ``t0`` to ``p1`` at ``t1`` (a hold when p0 == p1)."""

    t0: float
    t1: float
    p0: Vec3
    p1: Vec3

    def at(self, t: float) -> Vec3:
        span = self.t1 - self.t0
        if span <= 0:
            return self.p1
        f = (t - self.t0) / span
        f = 0.0 if f < 0 else 1.0 if f > 1 else f
        p0, p1 = self.p0, self.p1
        return (p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]), p0[2] + f * (p1[2] - p0[2]))


class Piecewise(Computed):
    """Motion made of consecutive segments; before the first it sits at the first point, after the
    last at the last point, unless ``loop`` repeats the whole sequence with its period."""

    static = False

    def __init__(self, segments: Sequence[Segment], loop: bool = False):
        if not segments:
            raise ValueError("a piecewise trajectory needs at least one segment")
        self.segments = list(segments)
        self._starts = [s.t0 for s in self.segments]
        self.t_begin = self.segments[0].t0
        self.t_end = self.segments[-1].t1
        self.loop = loop and self.t_end > self.t_begin
        self.static = all(s.p0 == s.p1 for s in self.segments) and len({s.p0 for s in self.segments}) == 1
        self.max_speed_mps = max(map(_speed, self.segments))
        """No faster than this anywhere (inf for a jump): lets the medium's grid bound where it can be."""

    def position(self, t: float) -> Vec3:
        if self.loop and t > self.t_end:
            period = self.t_end - self.t_begin
            t = self.t_begin + math.fmod(t - self.t_begin, period)
        if t <= self.t_begin:
            return self.segments[0].p0
        if t >= self.t_end:
            return self.segments[-1].p1
        index = bisect_right(self._starts, t) - 1
        return self.segments[index].at(t)

    def __repr__(self) -> str:
        return f"Piecewise({len(self.segments)} segments, loop={self.loop})"


def _speed(segment: Segment) -> float:
    length = math.dist(segment.p0, segment.p1)
    if length == 0.0:
        return 0.0
    span = segment.t1 - segment.t0
    return length / span if span > 0 else math.inf


def _vec(p: Sequence[float]) -> Vec3:
    return (float(p[0]), float(p[1]), float(p[2]))


def path_segments(start: Sequence[float], legs: Sequence[dict]) -> list[Segment]:
    """Turn validated legs (``hold_s``, ``to`` + ``speed_mps`` or ``to`` + ``duration_s``) into segments.

    A leg to where the vehicle already is takes no time with a speed (there is nowhere to go)."""
    t = 0.0
    here = _vec(start)
    segments: list[Segment] = []
    for leg in legs:
        if "hold_s" in leg:
            duration = float(leg["hold_s"])
            there = here
        else:
            there = _vec(leg["to"])
            if "duration_s" in leg:
                duration = float(leg["duration_s"])
            else:
                duration = math.dist(here, there) / float(leg["speed_mps"])
        segments.append(Segment(t, t + duration, here, there))
        t += duration
        here = there
    if not segments:
        segments.append(Segment(0.0, 0.0, here, here))
    return segments


def waypoint_segments(rows: Sequence[Sequence[float]]) -> list[Segment]:
    """Rows of ``[t, x, y, z]`` with increasing t, joined linearly."""
    points = [(float(r[0]), _vec(r[1:4])) for r in rows]
    if len(points) == 1:
        t, p = points[0]
        return [Segment(t, t, p, p)]
    return [Segment(t0, t1, p0, p1) for (t0, p0), (t1, p1) in zip(points, points[1:])]
