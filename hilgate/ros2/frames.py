"""Between ROS 2's axes and the scene's: positions, velocities and orientations.

The scene is NED (x north, y east, z down: depth is positive z) with FRD bodies (x forward, y right,
z down), as MAVLink reports them.  ROS 2 follows REP-103: ENU worlds (x east, y north, z up) with FLU
bodies (x forward, y left, z up); Gazebo with DAVE speaks so.  Stonefish, and marine stacks that keep
``*_ned`` frames (REP-105's suffix), speak NED with FRD bodies: ``frame: ned`` takes them as they are.

An orientation crosses by changing both bases: ``R_scene = C · R_ros · B`` where ``C`` turns the ROS
world's axes into the scene's and ``B`` the scene body's into the ROS body's (each its own inverse).
Pure arithmetic, no I/O.
"""

from __future__ import annotations

import math

__all__ = ["FRAMES", "position_to_scene", "position_from_scene", "orientation_to_scene",
           "orientation_from_scene", "rotate", "quaternion_from_rpy", "rpy_from_quaternion"]

FRAMES = ("enu", "ned")
_ENU_NED = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0))   # world axes, either way
_FLU_FRD = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))  # body axes, either way

Vec = tuple[float, float, float]
Quat = tuple[float, float, float, float]  # x, y, z, w as ROS writes them
Mat = tuple[Vec, Vec, Vec]


def position_to_scene(p: Vec, frame: str) -> Vec:
    return (p[1], p[0], -p[2]) if frame == "enu" else (p[0], p[1], p[2])


def position_from_scene(p: Vec, frame: str) -> Vec:
    return position_to_scene(p, frame)  # the swap is its own inverse


def _mul(a: Mat, b: Mat) -> Mat:
    return tuple(tuple(sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)) for i in range(3))  # type: ignore[return-value]


def matrix(q: Quat) -> Mat:
    """The rotation matrix of a quaternion (normalised first; a zero one is the identity)."""
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n == 0.0:
        return ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    x, y, z, w = x / n, y / n, z / n, w / n
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
            (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
            (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)))


def rpy_of(m: Mat) -> Vec:
    """Roll, pitch, yaw (Z-Y-X, radians) of a rotation matrix."""
    pitch = math.asin(max(-1.0, min(1.0, -m[2][0])))
    return math.atan2(m[2][1], m[2][2]), pitch, math.atan2(m[1][0], m[0][0])


def matrix_of_rpy(rpy: Vec) -> Mat:
    cr, sr = math.cos(rpy[0]), math.sin(rpy[0])
    cp, sp = math.cos(rpy[1]), math.sin(rpy[1])
    cy, sy = math.cos(rpy[2]), math.sin(rpy[2])
    return ((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
            (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
            (-sp, cp * sr, cp * cr))


def quaternion_of(m: Mat) -> Quat:
    """The quaternion of a rotation matrix, with w >= 0."""
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2
        q = ((m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, 0.25 * s)
    elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2]) * 2
        q = (0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s)
    elif m[1][1] > m[2][2]:
        s = math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2]) * 2
        q = ((m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s)
    else:
        s = math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1]) * 2
        q = ((m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s, (m[1][0] - m[0][1]) / s)
    return q if q[3] >= 0 else (-q[0], -q[1], -q[2], -q[3])


def rpy_from_quaternion(q: Quat) -> Vec:
    return rpy_of(matrix(q))


def quaternion_from_rpy(rpy: Vec) -> Quat:
    return quaternion_of(matrix_of_rpy(rpy))


def orientation_to_scene(q: Quat, frame: str) -> Vec:
    """A ROS orientation (body in world) as the scene's roll, pitch, yaw (NED world, FRD body)."""
    m = matrix(q)
    if frame == "enu":
        m = _mul(_mul(_ENU_NED, m), _FLU_FRD)
    return rpy_of(m)


def orientation_from_scene(rpy: Vec, frame: str) -> Quat:
    m = matrix_of_rpy(rpy)
    if frame == "enu":
        m = _mul(_mul(_ENU_NED, m), _FLU_FRD)
    return quaternion_of(m)


def rotate(q: Quat, v: Vec) -> Vec:
    """``v`` (in the body's axes) in the world's axes: a twist's linear velocity, for one."""
    m = matrix(q)
    return tuple(m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2] for i in range(3))  # type: ignore[return-value]
