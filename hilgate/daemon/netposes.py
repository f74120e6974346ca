"""The poses a daemon tells the others (``pose/<host>/<vehicle>``: live vehicles at each update, scripted
ones ``pose_rate_hz`` times a second) and those it takes from theirs, for the vehicles they own.

Kept apart from :mod:`.network` and :mod:`.nethearing` (which publish and hear transmissions): a pose
moves a :class:`~hilgate.sim.live_vehicle.RemoteVehicle` here, never a frame.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from .netcodec import MAX_TRANSMISSION, TIME_WINDOW_S, NetError, decode_pose, encode_pose, to_local
from ..core.inbox import Inbox
from ..sim.live_vehicle import LiveVehicle, RemoteVehicle

__all__ = ["Poses"]

INBOX_DEPTH = 4096  # poses per host waiting for the loop (each a few hundred bytes)
INBOX_BATCH = 256  # poses the loop takes per turn (then its other inputs get a turn)


class Poses:
    """This host's vehicles' poses out, the others' in (``network``: the daemon's
    :class:`~.network.Network`, whose session, hosts, scene and counters it shares)."""

    def __init__(self, network: Any):
        self.network = network
        self.publishers: dict[str, Any] = {}

    def _publisher(self, vehicle: str) -> Any:
        publisher = self.publishers.get(vehicle)
        if publisher is None:
            import zenoh

            network = self.network
            publisher = self.publishers[vehicle] = network.session.declare_publisher(
                f"{network.prefix}/pose/{network.host}/{vehicle}", allowed_destination=zenoh.Locality.REMOTE)
        return publisher

    # -- this host's -----------------------------------------------------------------------------

    def apply(self, scene: Any) -> None:
        """Publish each live vehicle of this host at each of its updates."""
        world = self.network.router.world
        for name, pose in world.poses.items():
            if (isinstance(pose, LiveVehicle) and not isinstance(pose, RemoteVehicle)
                    and world.local(scene.vehicles[name])):
                pose.listeners = [self._live_update(name, pose)]

    def _live_update(self, name: str, pose: LiveVehicle) -> Callable[[], None]:
        network = self.network

        def published() -> None:
            now = network.scheduler.now()
            position = pose.position(now)
            age = pose.age(now)
            velocity = None
            if pose.axes and all(state.velocity is not None for state in pose.axes.values()) and len(pose.axes) == 3:
                velocity = tuple(pose.axes[a].velocity for a in ("x", "y", "z"))
            self._publisher(name).put(encode_pose(network.host, network.epoch_ns, name, now - (age or 0.0),
                                                  position, velocity))

        return published

    def publish_every(self, interval: float) -> None:
        """Publish the scripted vehicles of this host every ``interval`` (wall) seconds, and refresh the
        network's status meanwhile."""
        network = self.network

        def publish() -> None:
            now = network.scheduler.now()
            world = network.router.world
            for name, pose in world.poses.items():
                vehicle = network.scene.vehicles.get(name)
                if vehicle is None or not world.local(vehicle) or pose.static:
                    continue
                if isinstance(pose, LiveVehicle):
                    continue  # published at each measurement
                position = pose.position(now)
                earlier = pose.position(max(0.0, now - 0.01)) if position is not None else None
                velocity = None
                if earlier is not None and now > 0.01:
                    velocity = tuple((a - b) / 0.01 for a, b in zip(position, earlier))
                self._publisher(name).put(encode_pose(network.host, network.epoch_ns, name, now, position, velocity))
            network.refresh_status()
            network.scheduler.after_wall(interval, publish)

        network.scheduler.after_wall(interval, publish)

    # -- the others' -----------------------------------------------------------------------------

    def subscribe(self) -> Any:
        """Hear the others' poses (one queue per host, taken on the loop); returns the subscriber."""
        network = self.network
        poses = Inbox(network.scheduler.post, self._on_poses, INBOX_DEPTH, batch=INBOX_BATCH)

        def on_pose(sample: Any) -> None:
            key, size = str(sample.key_expr), len(sample.payload)
            poses.put((key, sample.payload.to_bytes() if size <= MAX_TRANSMISSION else size),
                      source=network.key_host(key, "pose"))

        return network.session.declare_subscriber(f"{network.prefix}/pose/**", on_pose)

    def _on_poses(self, poses: list[tuple[str, bytes | int]], dropped: dict[str, int]) -> None:
        if dropped:
            self.network.counters["inbox_full"] += sum(dropped.values())
        for key, data in poses:
            self._on_pose(key, data)

    def _on_pose(self, key: str, data: bytes | int) -> None:
        network = self.network
        if isinstance(data, int):
            network.counters["bad_message"] += 1
            return
        try:
            message = decode_pose(data)
        except NetError:
            network.counters["bad_message"] += 1
            return
        if message["host"] == network.host:
            return
        if message["host"] != network.key_host(key, "pose"):
            network.counters["forged"] += 1
            return
        pose = network.router.world.poses.get(message["vehicle"])
        vehicle = network.scene.vehicles.get(message["vehicle"])
        view = network.hosts.get(message["host"])
        if vehicle is None or view is None or vehicle.host != message["host"] or message["position"] is None:
            return
        t = to_local(message["t"], message["epoch_ns"], network.epoch_ns)
        if abs(network.scheduler.now() - t) > TIME_WINDOW_S:
            network.counters["out_of_time"] += 1
            return
        if t < view.pose_t.get(message["vehicle"], -math.inf):
            network.counters["replay"] += 1  # older than one already applied: a replay, or overtaken
            return
        view.pose_t[message["vehicle"]] = t
        if isinstance(pose, RemoteVehicle):
            pose.update_from(t, message["position"], message["velocity"])
            network.router.world.medium.topology_changed()
