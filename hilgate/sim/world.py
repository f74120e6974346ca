"""A scene made live: pose sources, the medium, one simulated modem per ``sim`` link, and flows.

The same :class:`World` serves ``hilgate sim`` (virtual clock) and the daemon (real-time clock), and
:meth:`World.reconfigure` applies a new scene in place for the daemon's hot reload: modems keep
their FIFO and statistics, only what changed is rebuilt.  Every random stream is derived from the
scene seed and the name of what uses it, so adding a flow does not change the backoffs of a modem,
and a seed gives the same run byte for byte.
"""

from __future__ import annotations

import logging
import random
from typing import Any

from ..channel.prepare import ready_channels
from ..models.flows import FlowSource
from ..models.frame import BROADCAST
from ..models.medium import Medium
from ..models.modem import SimModem
from ..models.observer import Observer
from ..models.trajectories import PoseSource
from .live_vehicle import RemoteVehicle
from .pose_sources import build_pose
from ..scene import LinkSpec, Scene
from ..scene.diff import SceneDiff, diff

log = logging.getLogger(__name__)


def random_stream(seed: int, *names: str) -> random.Random:
    """A reproducible random stream per user (string seeds are hashed with SHA-512 by ``random``)."""
    return random.Random("/".join([str(seed), *names]))


class World:
    """``host``: the host this world serves in a scene spread over hosts (None: all of it, as
    ``hilgate sim`` and a one-host daemon).  Links of other hosts get a modem that sends only what
    their host tells (:meth:`hilgate.daemon.network.Network`) and hears nothing here; vehicles whose
    pose another host computes or measures get a :class:`RemoteVehicle` that host keeps up to date."""

    def __init__(self, scene: Scene, clock: Any, observer: Observer, seed: int | None = None,
                 host: str | None = None):
        self.scene = scene
        self.clock = clock
        self.observer = observer
        self.host = host
        self.seed = scene.seed if seed is None else seed
        self.medium = Medium(clock, ready_channels(scene.channels, scene.links).values())
        self.poses: dict[str, PoseSource] = {name: self._build_pose(v) for name, v in scene.vehicles.items()}
        self.modems: dict[str, SimModem] = {}
        for link in scene.links.values():
            if link.backend == "sim":
                self.add_modem(link)
        self.flows: list[FlowSource] = self._make_flows(scene, {})

    def local(self, spec: Any) -> bool:
        """Whether this world serves ``spec`` (a link, a vehicle or a camera)."""
        return self.host is None or spec.host is None or spec.host == self.host

    def _build_pose(self, vehicle: Any) -> PoseSource:
        pose = build_pose(vehicle)
        if self.local(vehicle) or pose.static:
            return pose  # a static pose is the same on every host: computed here, exactly
        return RemoteVehicle(vehicle)

    def _make_flows(self, scene: Scene, reuse: dict[Any, Any]) -> list[FlowSource]:
        flows = []
        for index, spec in enumerate(scene.flows):
            modem = self.modems.get(spec.src)
            if modem is not None and not self.local(scene.links[spec.src]):
                continue  # its host runs it
            if modem is None:
                log.warning("flow %d from %s: not a simulated link, ignored", index, spec.src)
                continue
            dst_addr = BROADCAST if spec.dst == "*" else scene.links[spec.dst].params.address
            stats = reuse.get(spec)
            if stats is None:
                stats = self.observer.add_flow(spec)
            flows.append(FlowSource(spec, modem, dst_addr, self.clock, random_stream(self.seed, "flow", str(index)), stats))
        return flows

    def add_modem(self, link: LinkSpec) -> SimModem:
        modem = SimModem(
            link.id, link.vehicle, self.poses[link.vehicle], link.params, self.clock, self.medium,
            random_stream(self.seed, "modem", link.id), self.observer, link.mac.build(),
        )
        modem.radio.listens = self.local(link)
        self.modems[link.id] = modem
        return modem

    def remove_modem(self, link_id: str) -> None:
        modem = self.modems.pop(link_id, None)
        if modem is not None:
            modem.close()

    def start(self) -> None:
        now = self.clock.now()
        for flow in self.flows:
            flow.start(now)

    def sample_poses(self, interval: float, record) -> None:
        """Put every vehicle's position in the trace every ``interval`` seconds, from now on (for the
        report's distance plots; live vehicles are only known this way)."""
        clock = self.clock

        def sample() -> None:
            t = clock.now()
            for name, pose in self.poses.items():
                position = pose.position(t)
                record({"t": round(t, 9), "ev": "pose", "vehicle": name,
                        "position": None if position is None else [round(c, 6) for c in position]})
            clock.at(t + interval, sample)

        clock.at(clock.now(), sample)

    def reconfigure(self, scene: Scene, changes: SceneDiff | None = None) -> None:
        """Apply ``scene`` in place: channels, vehicles, simulated modems and flows; ``changes`` (what
        :func:`hilgate.scene.diff.diff` found, computed here when not given) says what to rebuild."""
        changes = changes if changes is not None else diff(self.scene, scene)
        self.medium.channels.clear()
        self.medium.channels.update({c.name: c for c in ready_channels(scene.channels, scene.links).values()})
        for name in changes.vehicles:
            self.poses[name] = self._build_pose(scene.vehicles[name])
        for name in changes.vehicles_removed:
            self.poses.pop(name, None)
        for change in changes.links.values():
            if change.id in self.modems and (change.removed or change.after.backend != "sim"):
                self.remove_modem(change.id)
        for link in scene.links.values():
            if link.backend != "sim":
                continue
            modem = self.modems.get(link.id)
            if modem is None:
                self.add_modem(link)
                continue
            change = changes.links.get(link.id)
            if change is not None and change.modem_changed:
                modem.configure(link.params)
            modem.radio.listens = self.local(link)
            if change is not None and change.mac_changed:
                modem.set_mac(link.mac.build())
            modem.vehicle = link.vehicle
            modem.set_pose(self.poses[link.vehicle])
        reuse = {flow.spec: flow.stats for flow in self.flows}
        for flow in self.flows:
            flow.stop()
        self.scene = scene
        self.flows = self._make_flows(scene, reuse)
        self.start()
        self.medium.topology_changed()
