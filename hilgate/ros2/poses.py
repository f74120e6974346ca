"""A vehicle's pose from a ROS 2 topic: ``nav_msgs/msg/Odometry``, ``geometry_msgs/msg/PoseStamped`` or
``geometry_msgs/msg/PoseWithCovarianceStamped``, from a robot simulator (Gazebo/DAVE, Stonefish,
HoloOcean) or a real vehicle's localisation, moves the vehicle's modems exactly as MAVLink does.

Cyclone DDS calls :meth:`Ros2PoseFeed._on_data` on its own thread: each message is read there, checked
and turned into scene axes (:mod:`hilgate.ros2.frames`), and only the latest measurement is kept; the
loop is woken once (``post``) and applies whatever is latest when it runs.  A topic at 1 kHz costs the
loop no more than the loop can take, and never makes it wait.  Messages that cannot be a pose
(non-finite or absurd values, another ``frame_id`` than the scene asked for) are counted by cause and
logged once per cause, never applied.
"""

from __future__ import annotations

import logging
import math
import threading
from typing import Any, Callable

from cyclonedds.core import Listener

from . import frames
from .participant import DDSException, Participant, guarded

log = logging.getLogger(__name__)

__all__ = ["Ros2PoseFeed", "measurement", "BadPose", "MAX_COORDINATE_M"]

MAX_COORDINATE_M = 1e7
"""A coordinate beyond this (some ten thousand kilometres) is no vehicle's: refused as ``out_of_range``."""
MAX_SPEED_MPS = 1e3


class BadPose(ValueError):
    """A message that is no usable pose; ``cause`` names why (counted by it)."""

    def __init__(self, cause: str):
        super().__init__(cause)
        self.cause = cause


def _finite(values: tuple[float, ...], limit: float) -> None:
    for v in values:
        if not math.isfinite(v):
            raise BadPose("not_finite")
        if abs(v) > limit:
            raise BadPose("out_of_range")


def measurement(message: Any, type_name: str, frame: str, offset: tuple[float, float, float],
                frame_id: str | None = None) -> tuple[dict, dict | None, tuple]:
    """``(position, velocity or None, attitude)`` in the scene's axes (NED, FRD) of one message; raises
    :class:`BadPose`.  ``offset`` is where the ROS frame's origin lies in the scene."""
    if frame_id is not None and message.header.frame_id != frame_id:
        raise BadPose("frame_id")
    pose = message.pose if type_name == "geometry_msgs/msg/PoseStamped" else message.pose.pose
    p, o = pose.position, pose.orientation
    position = (float(p.x), float(p.y), float(p.z))
    orientation = (float(o.x), float(o.y), float(o.z), float(o.w))
    _finite(position, MAX_COORDINATE_M)
    _finite(orientation, 2.0)
    x, y, z = frames.position_to_scene(position, frame)
    scene = {"x": x + offset[0], "y": y + offset[1], "z": z + offset[2]}
    attitude = frames.orientation_to_scene(orientation, frame)
    velocity = None
    if type_name == "nav_msgs/msg/Odometry":  # the twist is in the child (body) frame: turn it into the world's
        v = message.twist.twist.linear
        body = (float(v.x), float(v.y), float(v.z))
        _finite(body, MAX_SPEED_MPS)
        vx, vy, vz = frames.position_to_scene(frames.rotate(orientation, body), frame)
        velocity = {"x": vx, "y": vy, "z": vz}
    return scene, velocity, attitude


MAX_TAKE = 10_000
"""Samples one listener call takes at most (the rest wake it again): a flood cannot keep it forever."""


def take_each(reader: Any, refuse: Callable[[str], Any]) -> Any:
    """The reader's samples one at a time: one that does not decode is taken out all the same and
    counted (``decode``) without costing the others."""
    for _ in range(MAX_TAKE):
        try:
            samples = reader.take(N=1)
        except DDSException:
            return  # the reader is being deleted
        except Exception:
            refuse("decode")
            continue
        if not samples:
            return
        yield samples[0]


class Ros2PoseFeed:
    """Reads ``topic`` for vehicle ``name``; ``apply(position, velocity, attitude)`` runs on the loop
    (through ``post``) with the latest measurement."""

    def __init__(self, name: str, participant: Participant, params: dict, default_frame: str,
                 apply: Callable[[dict, dict | None, tuple], Any], post: Callable[..., Any]):
        self.name = name
        self.topic = params["topic"]
        self.type_name = params["type"]
        self.frame = params["frame"] or default_frame
        self.frame_id = params["frame_id"]
        self.offset = tuple(params["offset"])
        self.apply = apply
        self.post = post
        self.participant = participant
        self.messages = 0   # read off the topic
        self.applied = 0    # measurements the loop applied (fewer than messages when they come faster)
        self.refused: dict[str, int] = {}
        self.lock = threading.Lock()
        self._latest: tuple | None = None
        self._posted = False
        listener = Listener(on_data_available=guarded(f"ros2 pose {name}")(self._on_data))
        self.reader = participant.reader(self.topic, self.type_name, listener, params["reliability"])

    def _on_data(self, reader: Any) -> None:
        """On Cyclone's thread: read everything there is, keep the latest good measurement."""
        for sample in take_each(reader, self._refuse):
            if not hasattr(sample, "header"):  # (by name: a DDS sample, or the invalid one of a writer gone)
                continue  # a writer went away (an invalid sample): no pose
            self.messages += 1
            try:
                latest = measurement(sample, self.type_name, self.frame, self.offset, self.frame_id)
            except BadPose as exc:
                self._refuse(exc.cause)
                continue
            with self.lock:
                self._latest = latest
                wake, self._posted = not self._posted, True
            if wake:
                self.post(self._apply)

    def _refuse(self, cause: str) -> None:
        with self.lock:
            first = cause not in self.refused
            self.refused[cause] = self.refused.get(cause, 0) + 1
        if first:
            log.warning("ros2 pose %s: a message on %s refused (%s); further ones are counted in STATUS",
                        self.name, self.topic, cause)

    def _apply(self) -> None:
        with self.lock:
            latest, self._latest, self._posted = self._latest, None, False
        if latest is not None:
            self.applied += 1
            self.apply(*latest)

    def status(self) -> dict:
        with self.lock:
            refused = dict(self.refused)
        return {"vehicle": self.name, "topic": self.topic, "type": self.type_name, "messages": self.messages,
                "applied": self.applied, "refused": refused}

    def stop(self) -> None:
        self.participant.delete(self.reader)


def start_pose_feed(setting: Any, params: dict) -> Ros2PoseFeed:
    """The ``ros2`` row of the pose-source table (:mod:`hilgate.scene.pose_table`): a topic read on the
    daemon's participant; Cyclone's thread keeps the latest measurement and the loop applies it, stamped
    with the model time it is applied at."""
    bridge = setting.ros2
    return Ros2PoseFeed(setting.vehicle, bridge.participant(), params, bridge.frame, setting.applying("ros2"),
                        setting.scheduler.post)
