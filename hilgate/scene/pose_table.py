"""The pose-source table: every live source of a vehicle's pose, declared once, as the driver table declares
the modems.

One :class:`PoseSourceRow` per source says

- its **name**, the key under a vehicle's ``pose:`` (live sources combine, axis by axis, with ``merge``);
- its **check**: ``"module:function"`` of ``check(node, path)``, which reads the source's keys from the
  scene (a ``scene.yaml_nodes.Node``) and returns them as a hashable tuple of (key, value) pairs, raising
  the node's error (FILE:LINE) when they are wrong;
- how the daemon **starts** it: ``"module:function"`` of ``start(setting, params)``, given the vehicle's
  :class:`hilgate.daemon.live_sources.FeedSetting` and the checked keys as a dict, returning the running
  feed (something with ``stop()``: a thread of its own, a DDS reader) that hands each measurement to
  ``setting.posting(...)`` from its thread or ``setting.applying(...)`` on the loop; None: the source is
  fed by another part of the scene (``aruco``: the camera that sees the marker).

The scene loader checks, and the daemon starts, every source through this table: adding a live pose
source means its module and a row here.  Installed packages add rows through the ``hilgate.pose_sources``
entry points (:mod:`hilgate.core.tables`).  Scripted poses (static, path, waypoints, controlled) are the
model's own and are not rows here (:mod:`hilgate.scene.vehicles`, :mod:`hilgate.sim.pose_sources`).

Why by name: checking a scene must not import pymavlink, OpenCV or Cyclone DDS; the rows name their
functions and :func:`hilgate.core.tables.resolve` imports a module only when it is used.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..core.tables import merge_entry_points, resolve

__all__ = ["PoseSourceRow", "POSE_SOURCES", "check_live"]


@dataclass(frozen=True)
class PoseSourceRow:
    """One live pose source (see the module's docstring)."""

    name: str
    title: str
    check: str         # "module:function" (node, path) -> tuple of (key, value)
    start: str | None  # "module:function" (FeedSetting, params: dict) -> a feed with stop(); None: fed elsewhere


POSE_SOURCES: dict[str, PoseSourceRow] = {row.name: row for row in (
    PoseSourceRow("mavlink", "MAVLink", "hilgate.scene.live_poses:mavlink_pose",
                  "hilgate.drivers.mavlink_source:start_pose_feed"),
    PoseSourceRow("aruco", "ArUco marker", "hilgate.scene.live_poses:aruco_pose", None),
    PoseSourceRow("ros2", "ROS 2 topic", "hilgate.scene.ros2:ros2_pose", "hilgate.ros2.poses:start_pose_feed"),
)}


def check_live(kind: str, node: Any, path: str) -> Any:
    """The checked keys of a vehicle's ``kind`` source (a row of the table)."""
    return resolve(POSE_SOURCES[kind].check)(node, path)


# last: a plug-in's row module imports this one (its row class, its options), complete by now
merge_entry_points("hilgate.pose_sources", POSE_SOURCES, lambda row: isinstance(row, PoseSourceRow))
