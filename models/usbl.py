"""A USBL fix from the simulated geometry: where the remote modem is, as the transceiver sees it.

An EvoLogics USBL modem reports, after each exchange, the remote modem's position in its own
transceiver frame (X/Y/Z), in the world (E/N/U) and as angles (``USBLLONG``, ``USBLANGLES``).  hilgate
knows both positions (paths, MAVLink, ArUco), so the emulator can print what a real USBL would: what a
lab needs to run a USBL-aided navigation filter on the bench.  Pure arithmetic, no I/O: the emulator
formats the lines.

Frames (the scene's is north-east-down):

- the transceiver's frame is the scene's frame rotated by its mounting orientation (roll, pitch, yaw;
  z-y-x Tait–Bryan, the aerospace convention): ``local = Rᵀ · (remote − own)``.  The vehicle's own
  attitude is not on the pose board, so the mounting is taken as the transceiver's attitude in the
  world (a vehicle that turns is not followed);
- E/N/U is the world difference in east-north-up;
- bearing = atan2(y, x) (from north / the transceiver's x axis towards east / y), elevation = the angle
  above the horizontal plane, asin(−z / r), in radians.

Noise (``bearing_sigma`` in radians, ``range_sigma_m``): the measured slant range is r + N(0, σ_r)
(never negative), the measured local bearing and elevation each get N(0, σ_b); X/Y/Z, E/N/U and the
world angles follow from those measurements.  Without noise nothing is drawn.  The reported accuracy
is the standard deviation of the position error, √(σ_r² + 2·(r·σ_b)²).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:
    import random

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class UsblParams:
    """A USBL transceiver: mounting (roll, pitch, yaw in radians) and its noise model."""

    orientation: Vec3 = (0.0, 0.0, 0.0)
    bearing_sigma: float = 0.0  # radians, on each of bearing and elevation
    range_sigma_m: float = 0.0


@dataclass(frozen=True)
class UsblFix:
    local: Vec3  # X/Y/Z in the transceiver's frame (m)
    enu: Vec3  # east, north, up (m)
    local_bearing: float
    local_elevation: float
    bearing: float
    elevation: float
    orientation: Vec3
    range_m: float  # the measured slant range
    accuracy_m: float


def rotation(roll: float, pitch: float, yaw: float) -> tuple[Vec3, Vec3, Vec3]:
    """The matrix (rows) that turns transceiver-frame vectors into the world's: Rz(yaw)·Ry(pitch)·Rx(roll)."""
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), \
        math.sin(yaw)
    return ((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
            (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
            (-sp, cp * sr, cp * cr))


def _apply(m: tuple[Vec3, Vec3, Vec3], v: Sequence[float]) -> Vec3:
    return (m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
            m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
            m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2])


def _transpose(m: tuple[Vec3, Vec3, Vec3]) -> tuple[Vec3, Vec3, Vec3]:
    return ((m[0][0], m[1][0], m[2][0]), (m[0][1], m[1][1], m[2][1]), (m[0][2], m[1][2], m[2][2]))


def angles(v: Sequence[float]) -> tuple[float, float]:
    """(bearing, elevation) of a north-east-down (or x-y-z-down) vector."""
    r = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if r == 0.0:
        return 0.0, 0.0
    return math.atan2(v[1], v[0]), math.asin(max(-1.0, min(1.0, -v[2] / r)))


def fix(own: Sequence[float], remote: Sequence[float], params: UsblParams,
        rng: "random.Random | None" = None) -> UsblFix:
    """The fix of ``remote`` seen from a transceiver at ``own`` (scene coordinates, metres)."""
    m = rotation(*params.orientation)
    delta = (remote[0] - own[0], remote[1] - own[1], remote[2] - own[2])
    local = _apply(_transpose(m), delta)
    r = math.sqrt(local[0] ** 2 + local[1] ** 2 + local[2] ** 2)
    bearing, elevation = angles(local)
    noisy = rng is not None and (params.bearing_sigma > 0.0 or params.range_sigma_m > 0.0)
    if noisy:
        if params.range_sigma_m > 0.0:
            r = max(0.0, r + rng.gauss(0.0, params.range_sigma_m))
        if params.bearing_sigma > 0.0:
            bearing += rng.gauss(0.0, params.bearing_sigma)
            elevation += rng.gauss(0.0, params.bearing_sigma)
        ce = math.cos(elevation)
        local = (r * ce * math.cos(bearing), r * ce * math.sin(bearing), -r * math.sin(elevation))
        bearing = math.atan2(math.sin(bearing), math.cos(bearing))  # back into (-π, π]
        elevation = math.atan2(math.sin(elevation), math.cos(elevation))
    world = _apply(m, local) if noisy else delta
    world_bearing, world_elevation = angles(world)
    accuracy = math.sqrt(params.range_sigma_m ** 2 + 2.0 * (r * params.bearing_sigma) ** 2)
    return UsblFix(local, (world[1], world[0], -world[2]), bearing, elevation, world_bearing, world_elevation,
                   params.orientation, r, accuracy)
