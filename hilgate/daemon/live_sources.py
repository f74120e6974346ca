"""Starts and stops what feeds the pose board in the daemon: the live pose sources of the pose-source table
(:mod:`hilgate.scene.pose_table`: MAVLink links, ROS 2 topics, a package's own), cameras, feedback.

Each runs in its own thread (or, for feedback, on the loop's timers) and hands measurements to the
loop with ``scheduler.post``, so the medium reads poses without ever waiting for a device.  A reload
stops everything and starts it again from the new scene (sockets and cameras must be released
before they can be opened again).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Callable, Protocol

from ..core.tables import resolve
from ..sim.live_vehicle import LiveVehicle
from ..scene import Scene
from ..scene.pose_table import POSE_SOURCES

log = logging.getLogger(__name__)


class PoseFeed(Protocol):
    """Something that measures vehicles' poses on a thread of its own (a MAVLink link, a camera, a ROS 2
    subscription) and hands them to the loop with ``scheduler.post``: made and started here when a scene
    names it, stopped on a reload or at exit (its sockets, devices or DDS reader released by then)."""

    def stop(self) -> None: ...


def _identity(heartbeat: tuple | None) -> Any:
    """The scene's ``heartbeat`` identity (system_id, component_id), or None: send no heartbeat."""
    from ..drivers.mavlink_identity import Identity

    if not heartbeat:
        return None
    options = dict(heartbeat)
    return Identity(options["system_id"], options["component_id"])


def _feedback_identity(vehicle: Any) -> Any:
    """Feedback goes as the vehicle's MAVLink heartbeat identity when the scene gives one (one
    identity for everything hilgate sends a vehicle), else as its companion computer (Feedback's default)."""
    if vehicle.pose.kind == "live":
        for kind, params in vehicle.pose.params:
            if kind == "mavlink" and dict(params)["heartbeat"]:
                return _identity(dict(params)["heartbeat"])
    return None


Measurement = Callable[[dict, "dict | None", "tuple | None"], None]  # (position, velocity, attitude)


@dataclass(frozen=True)
class FeedSetting:
    """What a pose source's ``start`` is given for one vehicle: the loop, the daemon's ROS 2 bridge, and
    the two ways a measurement reaches the vehicle's pose."""

    scheduler: Any
    ros2: Any
    vehicle: str
    pose: LiveVehicle

    def posting(self, source: str) -> Measurement:
        """For a feed's own thread: each measurement posted to the loop, stamped when the loop applies it."""
        post, now, pose = self.scheduler.post, self.scheduler.now, self.pose

        def deliver(position: dict, velocity: dict | None, attitude: tuple | None) -> None:
            post(lambda: pose.update(source, now(), position, velocity, attitude))

        return deliver

    def applying(self, source: str) -> Measurement:
        """On the loop: each measurement applied now, stamped with the model's time."""
        now, pose = self.scheduler.now, self.pose

        def apply(position: dict, velocity: dict | None, attitude: tuple | None) -> None:
            pose.update(source, now(), position, velocity, attitude)

        return apply


class LiveSources:
    def __init__(self, scheduler: Any, ros2: Any = None):
        self.scheduler = scheduler
        self.ros2 = ros2  # the daemon's Ros2Bridge: the participant ``ros2`` poses are read on
        self.feeds: dict[str, list[PoseFeed]] = {}  # row name → its running feeds
        self.cameras: dict[str, Any] = {}  # name → the camera's PoseFeed (drivers.aruco.CameraThread)
        self.feedback: list[Any] = []

    def apply(self, scene: Scene, poses: dict[str, Any], local: Any = lambda spec: True) -> None:
        """Start the sources of the vehicles and cameras this host serves (``local``, in a scene spread
        over hosts: the others' are measured on their hosts and published)."""
        self.close()
        for name, vehicle in scene.vehicles.items():
            if not local(vehicle):
                continue
            pose = poses.get(name)
            if vehicle.pose.kind == "live" and isinstance(pose, LiveVehicle):
                self._start_sources(name, pose, vehicle.pose.params)
            if vehicle.feedback:
                self._start_feedback(name, pose, dict(vehicle.feedback), _feedback_identity(vehicle))
        for camera in scene.cameras.values():
            if local(camera):
                self._start_camera(scene, camera, poses)

    def _start_sources(self, name: str, pose: LiveVehicle, sources: tuple) -> None:
        """Each of a vehicle's live sources that its row starts (``aruco`` is started by its camera)."""
        setting = FeedSetting(self.scheduler, self.ros2, name, pose)
        for kind, params in sources:
            start = POSE_SOURCES[kind].start
            if start is not None:
                self.feeds.setdefault(kind, []).append(resolve(start)(setting, dict(params)))

    def _start_feedback(self, name: str, pose: Any, params: dict, identity: Any) -> None:
        from ..drivers.mavlink_source import Feedback

        now = self.scheduler.now
        try:
            feedback = Feedback(name, params["url"], params["message"], params["rate_hz"], params["origin"],
                                params["system_id"], lambda: pose.position(now()),
                                lambda: pose.attitude, self.scheduler, identity)
        except ValueError as exc:  # it would send as a ground station: send nothing
            log.error("%s; no feedback sent", exc)
            return
        self.feedback.append(feedback)

    def _start_camera(self, scene: Scene, camera: Any, poses: dict[str, Any]) -> None:
        from ..drivers.aruco import CameraThread, Estimator, FixedCameraTracker, OnboardTracker, load_calibration

        estimator = Estimator(load_calibration(camera.calibration), camera.marker_length_m, camera.dictionary)
        if camera.fixed is not None:
            markers = {}
            for name, vehicle in scene.vehicles.items():
                for kind, params in (vehicle.pose.params if vehicle.pose.kind == "live" else ()):
                    options = dict(params)
                    if kind == "aruco" and options["camera"] == camera.name:
                        markers[options["marker"]] = (name, options["offset"])
            tracker = FixedCameraTracker(estimator, camera.fixed[0], camera.fixed[1], markers)
        else:
            vehicle, position, rpy = camera.onboard
            tracker = OnboardTracker(estimator, vehicle, position, rpy,
                                     {marker: (p, r) for marker, p, r in camera.map})
        post, now = self.scheduler.post, self.scheduler.now

        def deliver(sightings: list) -> None:
            def apply() -> None:
                for sighting in sightings:
                    pose = poses.get(sighting.vehicle)
                    if isinstance(pose, LiveVehicle):
                        x, y, z = sighting.position
                        pose.update("aruco", now(), {"x": x, "y": y, "z": z}, None, sighting.attitude)

            post(apply)

        thread = CameraThread(camera.name, camera.source, tracker, deliver, camera.fps)
        thread.start()
        self.cameras[camera.name] = thread

    def status(self) -> list[dict]:
        return [{"name": name, "fps": round(thread.fps, 1), "frames": thread.frames, "error": thread.error}
                for name, thread in self.cameras.items()]

    def ros2_status(self) -> list[dict]:
        return [source.status() for source in self.feeds.get("ros2", ())]

    def close(self) -> None:
        for feed in [*(feed for feeds in self.feeds.values() for feed in feeds), *self.cameras.values()]:
            feed.stop()
        for feedback in self.feedback:
            feedback.close()
        self.feeds, self.cameras, self.feedback = {}, {}, []
