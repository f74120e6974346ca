"""What hilgate publishes to ROS 2 when the scene's ``ros2.publish`` asks for it, on the loop's timers
(wall clock):

- ``poses``: every vehicle's pose as ``geometry_msgs/msg/PoseStamped`` on ``<ns>/<vehicle>/pose``
  (``header.frame_id`` the section's ``frame_id``, axes its ``frame``; a vehicle without a position, or
  whose pose is stale and dropped, is not published until it has one again);
- ``tf``: the same poses as ``tf2_msgs/msg/TFMessage`` on ``/tf`` (at most :data:`CHUNK` transforms in one),
  ``frame_id`` → vehicle name;
- ``diagnostics``: ``diagnostic_msgs/msg/DiagnosticArray`` on ``/diagnostics``, one status per link of
  this host (``hilgate: <link>``, OK while up and READY, WARN while BUSY, ERROR when down; its counters
  as key/values) and one per live vehicle (OK while fresh, STALE when stale or gone), in arrays of at
  most :data:`CHUNK` statuses (as many nodes' arrays are: an aggregator merges them).

It reads the world through two functions the daemon gives it, so it knows nothing of the router.
An orientation is published only for vehicles that report one (a live vehicle's attitude); the others
carry the identity quaternion.
"""

from __future__ import annotations

import logging
import time
from typing import Any, Callable, Iterable

from . import frames
from .idl import message_class
from .participant import DDSException, Participant

log = logging.getLogger(__name__)

__all__ = ["Publisher", "VehicleState", "OK", "WARN", "ERROR", "STALE"]

OK, WARN, ERROR, STALE = 0, 1, 2, 3
POSE = "geometry_msgs/msg/PoseStamped"
TF = "tf2_msgs/msg/TFMessage"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"

VehicleState = tuple  # (name, position NED or None, attitude (roll, pitch, yaw) or None, age_s or None, stale)


def stamp_of(now: float, message: Any) -> None:
    message.sec, message.nanosec = int(now), int((now % 1.0) * 1e9)


CHUNK = 16
"""Messages (poses, transforms, link statuses) built in one turn of the loop: a 1 000-link scene's
/diagnostics built at once holds the loop some 50 ms; in turns of 16, under a millisecond each."""


class Publisher:
    """Publishes what ``spec`` (a :class:`hilgate.scene.ros2.Ros2Spec`) lists.  ``vehicles()`` and
    ``links()`` list the world's vehicles and links when a timer fires, each as a function that gives
    its state when its turn comes (a :data:`VehicleState`, a link's STATUS); ``token`` makes names ROS
    names.  A publication still under way when the next is due skips it (counted)."""

    def __init__(self, participant: Participant, scheduler: Any, spec: Any,
                 vehicles: Callable[[], list[Callable[[], VehicleState]]], links: Callable[[], list[Callable[[], dict]]],
                 token: Callable[[str], str]):
        self.participant = participant
        self.scheduler = scheduler
        self.spec = spec
        self.vehicles = vehicles
        self.links = links
        self.token = token
        self.namespace = spec.namespace.rstrip("/")
        self.pose_writers: dict[str, Any] = {}
        self.tf_writer = self.diag_writer = None
        self.published = {"poses": 0, "tf": 0, "diagnostics": 0}
        self.failed = 0   # writes refused (a reliable writer's history full of unacknowledged samples)
        self.skipped = 0  # publications not started because the previous one was not done
        self.timers: list[Any] = []
        self.closed = False
        self.Pose, self.Tf, self.Diag = message_class(POSE), message_class(TF), message_class(DIAGNOSTICS)
        self.Transform = message_class("geometry_msgs/msg/TransformStamped")
        self.Status, self.KeyValue = message_class("diagnostic_msgs/msg/DiagnosticStatus"), message_class("diagnostic_msgs/msg/KeyValue")
        if spec.tf is not None:
            self.tf_writer = participant.writer("/tf", TF, spec.tf.reliability, depth=100)
            self._every(spec.tf.rate_hz, self.vehicles, self._publish_tf)
        if spec.diagnostics is not None:
            self.diag_writer = participant.writer("/diagnostics", DIAGNOSTICS, spec.diagnostics.reliability)
            self._every(spec.diagnostics.rate_hz, lambda: [*self.links(), *self.vehicles()], self._publish_diagnostics)
        if spec.poses is not None:
            self._every(spec.poses.rate_hz, self.vehicles, self._publish_poses)

    def _every(self, rate_hz: float, collect: Callable[[], list], publish: Callable[[float, list], Any]) -> None:
        """Every ``1/rate_hz`` s of wall clock: ``publish(now, chunk)`` for each :data:`CHUNK` of what
        ``collect()`` lists, one chunk per turn of the loop."""
        period = 1.0 / rate_hz
        index = len(self.timers)
        self.timers.append(None)
        busy = [False]

        def turn(now: float, items: list, start: int) -> None:
            if self.closed:
                return
            try:
                publish(now, [get() for get in items[start:start + CHUNK]])
            except Exception as exc:  # a bug costs one publication, never the loop
                log.error("ros2 publication failed: %s: %s", type(exc).__name__, exc)
            if start + CHUNK < len(items):
                self.scheduler.after_wall(0.0, turn, now, items, start + CHUNK)
            else:
                busy[0] = False

        def tick() -> None:
            self.timers[index] = self.scheduler.after_wall(period, tick)
            if busy[0]:
                self.skipped += 1
                return
            items = collect()
            if items:
                busy[0] = True
                turn(time.time(), items, 0)

        self.timers[index] = self.scheduler.after_wall(period, tick)

    def _write(self, writer: Any, message: Any, what: str) -> None:
        try:
            writer.write(message)
            self.published[what] += 1
        except DDSException:
            self.failed += 1

    def _pose(self, position: tuple, attitude: tuple | None) -> tuple:
        frame = self.spec.frame
        ros = frames.position_from_scene(position, frame)
        rotation = frames.orientation_from_scene(attitude, frame) if attitude is not None else (0.0, 0.0, 0.0, 1.0)
        return ros, rotation

    def _publish_poses(self, now: float, vehicles: list) -> None:
        for name, position, attitude, _age, _stale in vehicles:
            if position is None:
                continue
            writer = self.pose_writers.get(name)
            if writer is None:
                writer = self.pose_writers[name] = self.participant.writer(
                    f"{self.namespace}/{self.token(name)}/pose", POSE, self.spec.poses.reliability)
            (x, y, z), (qx, qy, qz, qw) = self._pose(position, attitude)
            message = self.Pose()
            stamp_of(now, message.header.stamp)
            message.header.frame_id = self.spec.frame_id
            p, o = message.pose.position, message.pose.orientation
            p.x, p.y, p.z, o.x, o.y, o.z, o.w = x, y, z, qx, qy, qz, qw
            self._write(writer, message, "poses")

    def _publish_tf(self, now: float, vehicles: list) -> None:
        message = self.Tf()
        for name, position, attitude, _age, _stale in vehicles:
            if position is None:
                continue
            (x, y, z), (qx, qy, qz, qw) = self._pose(position, attitude)
            transform = self.Transform()
            stamp_of(now, transform.header.stamp)
            transform.header.frame_id = self.spec.frame_id
            transform.child_frame_id = self.token(name)
            t, r = transform.transform.translation, transform.transform.rotation
            t.x, t.y, t.z, r.x, r.y, r.z, r.w = x, y, z, qx, qy, qz, qw
            message.transforms.append(transform)
        if message.transforms:
            self._write(self.tf_writer, message, "tf")

    def _publish_diagnostics(self, now: float, states: list) -> None:
        message = self.Diag()
        stamp_of(now, message.header.stamp)
        for state in states:
            status = self._link_status(state) if isinstance(state, dict) else self._vehicle_status(state)
            if status is not None:
                message.status.append(status)
        if message.status:
            self._write(self.diag_writer, message, "diagnostics")

    def _link_status(self, link: dict) -> Any:
        KeyValue = self.KeyValue
        up = link["state"] == "up"
        level = OK if up and link["ready"] else WARN if up else ERROR
        values = [KeyValue(key, str(link[key])) for key in
                  ("state", "ready", "tx_packets", "rx_packets", "drops", "unread", "fifo_bytes")]
        values += [KeyValue(f"drops.{cause}", str(n)) for cause, n in sorted(link["drop_causes"].items())]
        if up:
            text = "ready" if link["ready"] else "busy"
        else:
            text = link.get("reason") or link["state"]
        return self.Status(level, f"hilgate: {link['id']}", str(text), str(link["backend"]), values)

    def _vehicle_status(self, vehicle: tuple) -> Any:
        name, position, _attitude, age, stale = vehicle
        if age is None and position is not None:
            return None  # scripted: always known, nothing to diagnose
        KeyValue = self.KeyValue
        level = STALE if stale or position is None else OK
        values = [KeyValue("age_s", "none" if age is None else f"{age:.3f}"),
                  KeyValue("position", "none" if position is None else " ".join(f"{v:.3f}" for v in position))]
        return self.Status(level, f"hilgate: vehicle {name}", "stale" if level == STALE else "fresh", "vehicle", values)

    def status(self) -> dict:
        return {"published": dict(self.published), "failed": self.failed, "skipped": self.skipped}

    def close(self) -> None:
        self.closed = True
        for timer in self.timers:
            self.scheduler.cancel(timer)
        self.timers = []
        for writer in [*self.pose_writers.values(), self.tf_writer, self.diag_writer]:
            if writer is not None:
                self.participant.delete(writer)
        self.pose_writers = {}
