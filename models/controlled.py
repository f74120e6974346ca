"""A simulated vehicle steered by an application: go to a point, or hold a velocity, at most at its
maximum speed.  Pure model: it integrates its motion analytically from the last command, so virtual
and real time give the same positions for the same commands."""

from __future__ import annotations

import math

from .trajectories import Computed, Vec3


class Controlled(Computed):
    static = False
    max_speed_mps = math.inf
    """(Not its top speed: an application may steer it at any moment, and the medium's grid is not
    told; every transmission computes its distances.)"""

    def __init__(self, start: Vec3, max_speed_mps: float):
        self.max_speed = float(max_speed_mps)
        self._t = 0.0
        self._p: Vec3 = (float(start[0]), float(start[1]), float(start[2]))
        self.target: Vec3 | None = None
        self.velocity: Vec3 | None = None

    def position(self, t: float) -> Vec3:
        dt = max(0.0, t - self._t)
        p = self._p
        if self.velocity is not None:
            v = self.velocity
            return (p[0] + v[0] * dt, p[1] + v[1] * dt, p[2] + v[2] * dt)
        if self.target is not None:
            remaining = math.dist(p, self.target)
            step = self.max_speed * dt
            if step >= remaining or remaining == 0:
                return self.target
            f = step / remaining
            q = self.target
            return (p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1]), p[2] + f * (q[2] - p[2]))
        return p

    def _settle(self, t: float) -> None:
        self._p = self.position(t)
        self._t = max(self._t, t)

    def go_to(self, t: float, target: Vec3) -> None:
        """From time ``t`` head for ``target`` in a straight line at the maximum speed, then stop there."""
        self._settle(t)
        self.target = (float(target[0]), float(target[1]), float(target[2]))
        self.velocity = None

    def set_velocity(self, t: float, velocity: Vec3) -> None:
        """From time ``t`` move at ``velocity`` (m/s, NED), scaled down to the maximum speed if faster."""
        self._settle(t)
        speed = math.sqrt(sum(c * c for c in velocity))
        scale = 1.0 if speed <= self.max_speed or speed == 0 else self.max_speed / speed
        self.velocity = tuple(float(c) * scale for c in velocity)  # type: ignore[assignment]
        self.target = None

    def stop(self, t: float) -> None:
        self._settle(t)
        self.target = None
        self.velocity = None

