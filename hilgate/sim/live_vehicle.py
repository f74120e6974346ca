"""A live vehicle's pose (the pose board of the daemon): the latest pose of a vehicle whose position comes from the world (MAVLink,
a camera), as the medium sees it.

A :class:`LiveVehicle` is a pose source like the scripted ones.  Sources update it, possibly for only
some axes (``merge``: x and y from the camera, z, the depth, from MAVLink).  When its pose is older
than ``stale_after_s`` it is *stale*: ``hold`` keeps the last position, ``drop`` makes the vehicle
vanish (its modems hear nothing and are heard by nobody).  Over gaps shorter than ``extrapolate_s``
the position is carried on along the last velocity, when a source gives one.
"""

from __future__ import annotations

import math

from dataclasses import dataclass
from typing import Any

from ..models.trajectories import Vec3

AXES = ("x", "y", "z")


@dataclass
class AxisState:
    value: float
    velocity: float | None
    t: float
    source: str


class LiveVehicle:
    static = False
    max_speed_mps = math.inf  # a live source promises no top speed

    def __init__(self, name: str, initial: Vec3 | None = None, stale_after_s: float = 2.0, stale: str = "hold",
                 extrapolate_s: float = 0.0, merge: dict[str, str] | None = None):
        self.name = name
        self.initial = initial
        self.stale_after_s = stale_after_s
        self.policy = stale
        self.extrapolate_s = extrapolate_s
        self.merge = merge or {}
        self.axes: dict[str, AxisState] = {}
        if initial is not None:
            self.axes = {a: AxisState(float(v), None, float("-inf"), "initial") for a, v in zip(AXES, initial)}
        self.attitude: tuple[float, float, float] | None = None
        self.extra: dict[str, Any] = {}
        self.listeners: list[Any] = []  # called after each update (the network publishes it to other hosts)

    def update(self, source: str, t: float, position: dict[str, float], velocity: dict[str, float] | None = None,
               attitude: tuple[float, float, float] | None = None) -> None:
        """A measurement from ``source`` at model time ``t`` for some axes (``{"x": …, "z": …}``)."""
        for axis, value in position.items():
            owner = self.merge.get(axis)
            if owner is not None and owner != source:
                continue  # this axis is another source's
            speed = None if velocity is None else velocity.get(axis)
            self.axes[axis] = AxisState(float(value), speed, t, source)
        if attitude is not None:
            self.attitude = attitude
        for listener in self.listeners:
            listener()

    def age(self, t: float) -> float | None:
        """Seconds since the oldest measured axis was measured; None before any measurement."""
        measured = [state.t for state in self.axes.values() if state.source != "initial"]
        if not measured:
            return None
        return max(0.0, t - min(measured))

    def stale(self, t: float) -> bool:
        age = self.age(t)
        return age is not None and age > self.stale_after_s

    def position(self, t: float) -> Vec3 | None:
        """The ``initial`` position until measurements come, then the measured one; None while an
        axis is unknown, or when the pose is stale and the policy is ``drop``."""
        if len(self.axes) < 3:
            return None
        if self.policy == "drop" and self.stale(t):
            return None
        result = []
        for axis in AXES:
            state = self.axes[axis]
            value = state.value
            gap = t - state.t
            if state.velocity is not None and 0 < gap <= self.extrapolate_s:
                value += state.velocity * gap
            result.append(value)
        return (result[0], result[1], result[2])

    def sources(self) -> str:
        return "+".join(sorted({s.source for s in self.axes.values()})) or "none"


class RemoteVehicle(LiveVehicle):
    """A vehicle whose pose another host computes or measures (its ``host:``), as that host publishes
    it: position, velocity and the model time it was measured at, in this host's model time.  Between
    updates it is carried on along the velocity (over at most ``extrapolate_s``, at least one second:
    scripted vehicles are published ten times a second); with no update yet it has no position, so its
    modems are heard by nobody rather than from a place it never was."""

    def __init__(self, spec: Any):
        live = spec.pose.kind == "live"  # measured: carried on as its own host does; scripted: smoothly
        super().__init__(spec.name, None, spec.stale_after_s, spec.stale,
                         spec.extrapolate_s if live else max(spec.extrapolate_s, 1.0))
        self.host = spec.host

    def update_from(self, t: float, position: Vec3, velocity: Vec3 | None) -> None:
        axes = dict(zip(AXES, position))
        speeds = None if velocity is None else dict(zip(AXES, velocity))
        if self.axes and min(state.t for state in self.axes.values()) > t:
            return  # an older update overtaken by a newer one
        if speeds is None and self.axes:  # a transmission's exact position: keep the published velocity
            speeds = {axis: state.velocity for axis, state in self.axes.items() if state.velocity is not None}
        self.update("net", t, axes, speeds or None)
