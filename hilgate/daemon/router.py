"""Link id → backend, with the endpoints in front.

A :class:`~hilgate.daemon.routed_link.RoutedLink` has one backend and the endpoints its doors opened (the dccomms POSIX queues, its
Unix socket and the clients on it, an emulated modem), all behind the narrow interface of
:mod:`hilgate.core.endpoint`: the router imports no endpoint class.  Endpoints live as long as the
link id is in the scene; the backend behind them may be reconfigured or replaced by a reload, which
applications do not notice except for the new behaviour.  The :class:`Router` applies scenes: the
first one builds everything, a reload changes only what :func:`hilgate.scene.diff.diff` says changed.
"""

from __future__ import annotations

import logging
import math
from typing import Any, Callable

from .access import LinkLock
from .accounts import LinkAccount
from .routed_link import RoutedLink
from .stale_poses import staleness
from .steering import vehicle_request
from ..core.backend import Backend
from ..core.endpoint import Door
from ..drivers.table import DRIVERS, open_backend
from ..models.frame import BROADCAST
from ..scene import LinkSpec, Scene
from ..scene.diff import SceneDiff, diff
from ..scene.view import link_changes, link_view as scene_view_link, scene_view, view_hash
from ..sim.sim_backend import SimBackend
from ..sim.recorder import Recorder
from ..sim.world import World

log = logging.getLogger(__name__)


class Router:
    """Applies scenes: builds the links (a lock, the doors' endpoints, a backend) and changes only what
    a reload changed (:func:`hilgate.scene.diff.diff`).  The daemon gives it the doors."""

    def __init__(self, scheduler: Any, recorder: Recorder, doors: list[Door] | None = None,
                 max_link_clients: int = 32, host: str | None = None, lock_dir: str = ""):
        self.lock_dir = lock_dir  # where the links' locks are (hilgate.daemon.access.lock_directory)
        self.host = host  # in a scene spread over hosts, the links of this host only (scene/hosts.py)
        self.network: Any = None  # hilgate.daemon.network.Network, when there are several hosts
        self.scheduler = scheduler
        self.recorder = recorder
        self.doors: list[Door] = list(doors or [])
        self.max_link_clients = max_link_clients
        self.links: dict[str, RoutedLink] = {}
        self.accounts: dict[str, LinkAccount] = {}  # every link this daemon served in the run, even removed ones
        self.world: World | None = None
        self.scene: Scene | None = None
        self._names: dict[tuple[str, int], str] = {}
        self.backend_factories: dict[str, Callable[[LinkSpec], Backend]] = {
            "sim": self._sim_backend, **dict.fromkeys(DRIVERS, self._driver_backend)}

    def port(self, link_id: str) -> RoutedLink | None:
        """The link a socket client names in its HELLO."""
        return self.links.get(link_id)

    def scene_seed(self) -> int:
        """The scene's seed (0 before the first scene): the links' own random streams start from it."""
        return self.scene.seed if self.scene is not None else 0

    def address_of(self, link: RoutedLink, name: str) -> int | None:
        """The address that ``name`` (a link of the scene, or a vehicle with one link on the channel) answers to
        on ``link``'s channel; None when nothing there answers to it."""
        scene = self.scene
        if scene is None:
            return None
        channel = link.spec.params.tx_channel
        spec = scene.links.get(name)
        if spec is None:
            mine = [s for s in scene.links.values() if s.vehicle == name and s.params.rx_channel == channel]
            spec = mine[0] if len(mine) == 1 else None
        if spec is None or spec.params.rx_channel != channel:
            return None
        other = self.links.get(spec.id)
        return other.address if other is not None else spec.params.address

    def link_name(self, channel: str, address: int) -> str:
        return self._names.get((channel, address), f"addr:{address}")

    def _sim_backend(self, spec: LinkSpec) -> Backend:
        assert self.world is not None
        return SimBackend(self.world.modems[spec.id], self.link_name, spec.everyone_in_range, spec.limits)

    def addressed_to_nobody(self, channel: str, address: int) -> bool:
        return address != BROADCAST and (channel, address) not in self._names

    def readdress(self, link: RoutedLink, old: int, new: int) -> None:
        """A link answers to another address (``AT!AL``): the trace names and "addressed to nobody"
        follow it."""
        channel = link.spec.params.rx_channel
        if self._names.get((channel, old)) == link.id:
            del self._names[(channel, old)]
        self._names[(channel, new)] = link.id

    def _driver_backend(self, spec: LinkSpec) -> Backend:
        """A real modem's driver, as the backend table (:mod:`hilgate.drivers.table`) says to open it."""
        return open_backend(spec, self.scheduler, self.recorder.event)

    def apply(self, scene: Scene) -> None:
        """Build the first scene, or change the running one into ``scene`` (already validated).  A
        reload is traced once applied (a ``reload`` line: :meth:`_trace_reload`), even in part."""
        before = self.scene
        changes = diff(before, scene)
        if before is None:
            self._apply(scene, changes)
            return
        try:
            self._apply(scene, changes)
        except BaseException:
            self._trace_reload(before, scene, changes, partial=True)
            raise
        self._trace_reload(before, scene, changes, partial=False)

    def _trace_reload(self, before: Scene, after: Scene, changes: SceneDiff, partial: bool) -> None:
        """The ``reload`` line: when, the new scene's hash and the scene itself (as the ``run`` line has
        it, so that ``hilgate fit`` and ``report`` know what each link was from here on), and per link
        what changed (backend before/after, parameters).  Events before it belong to the old scene."""
        view = scene_view(after)
        changed = {}
        for link_id in changes.links:
            old = before.links.get(link_id)
            changed[link_id] = link_changes(None if old is None else scene_view_link(old), view["links"].get(link_id))
        line: dict[str, Any] = {"t": round(self.scheduler.now(), 9), "ev": "reload", "scene": after.name,
                                "scene_hash": view_hash(view), "changes": changed}
        if changes.vehicles or changes.vehicles_removed:
            line["vehicles"] = sorted(changes.vehicles | changes.vehicles_removed)
        if changes.channels_changed:
            line["channels_changed"] = True
        if changes.flows_changed:
            line["flows_changed"] = True
        if partial:
            line["partial"] = True  # applying failed half-way: the daemon's log says why
        line["scene_view"] = view
        self.recorder.event(line)

    def summary(self) -> list[dict[str, Any]]:
        """Every link this daemon served during the run, with its totals and its backend periods."""
        now = self.scheduler.now()
        return [account.summary(now) for account in self.accounts.values()]

    def _apply(self, scene: Scene, changes: SceneDiff) -> None:
        self._names = {(l.params.rx_channel, l.params.address): l.id for l in scene.links.values()}
        self._names.update({(l.params.rx_channel, BROADCAST): "*" for l in scene.links.values()})
        for link in self.links.values():  # links an AT!AL readdressed keep their address if unchanged
            if link.readdressed is not None and link.id in scene.links:
                self._names[(link.spec.params.rx_channel, link.readdressed)] = link.id
        first = self.world is None
        if first:
            self.world = World(scene, self.scheduler, self.recorder, host=self.host)
        else:
            self.world.reconfigure(scene, changes)
        self.scene = scene
        for change in changes.links.values():
            if change.removed and change.id in self.links:
                log.info("link %s removed", change.id)
                self.links.pop(change.id).close()
        # A real modem's driver opens its port at once; its modem may be an emulated one of this scene, whose
        # pty the emulated link's door makes: every link's doors first, the drivers after, whatever the
        # order of the scene (a driver listed first looked for a pty not yet there: a warning, a retry)
        drivers: list[tuple[RoutedLink, LinkSpec]] = []
        for spec in scene.links.values():
            change = changes.links.get(spec.id)
            link = self.links.get(spec.id)
            if not self.world.local(spec):
                if link is not None:
                    log.info("link %s is served by host %s now", spec.id, spec.host)
                    self.links.pop(spec.id).close()
                continue
            if link is None:
                self._add(spec, announce=not first, drivers=drivers)
                continue
            if change is None:
                continue
            link.update(spec, change.endpoints_changed)
            if change.backend_changed:
                log.info("link %s: backend %s -> %s", spec.id, change.before.backend, spec.backend)
                self._set_backend(link, spec, drivers)
            elif link.rebind(self.world.modems.get(spec.id)):
                log.info("link %s reconfigured", spec.id)
            link.state_changed()
        for link, spec in drivers:
            link.set_backend(self.backend_factories[spec.backend](spec), spec.backend)
        if first:
            self.world.start()

    def _set_backend(self, link: RoutedLink, spec: LinkSpec, drivers: list[tuple[RoutedLink, LinkSpec]]) -> None:
        """Give ``link`` its backend now, or, a real modem's driver, once every link's doors are open."""
        if spec.backend in DRIVERS:
            drivers.append((link, spec))
        else:
            link.set_backend(self.backend_factories[spec.backend](spec), spec.backend)

    def _add(self, spec: LinkSpec, announce: bool, drivers: list[tuple[RoutedLink, LinkSpec]]) -> None:
        lock = LinkLock(spec.id, self.lock_dir)  # one daemon per link id of this user, or refused here
        account = self.accounts.get(spec.id) or LinkAccount(spec.id)  # a link re-added goes on counting
        link = RoutedLink(spec, self, account)
        link.lock = lock
        try:
            link.open_doors(self.doors)
        except BaseException:
            link.close()
            raise
        self.links[spec.id] = link
        self.accounts[spec.id] = account
        self._set_backend(link, spec, drivers)
        if announce:
            log.info("link %s added (%s)", spec.id, spec.backend)

    def command(self, link: RoutedLink, request: Any) -> dict[str, Any]:
        """A client's request about its link (``{"class": "STATUS"}``: the link's status) or its vehicle
        (:func:`.steering.vehicle_request`: POSE, GOTO, VELOCITY, STOP)."""
        if not isinstance(request, dict):
            return {"class": "ERROR", "error": "a request is a JSON object with a class"}
        if request.get("class") == "STATUS":
            return {"class": "STATUS", "link": link.status()}
        return vehicle_request(self.world, link.spec.vehicle, request, self.scheduler.now())

    def status(self) -> dict[str, Any]:
        status = {"links": [link.status() for link in self.links.values()], "vehicles": self.vehicle_status()}
        if self.network is not None:
            status["network"] = self.network.status()
        return status

    def vehicle_status(self) -> list[dict[str, Any]]:
        """Every vehicle now: its pose source, position (None: unknown), the age of its pose, whether it is
        stale (:func:`.stale_poses.staleness`) and its heading when its source tells it."""
        assert self.world is not None and self.scene is not None
        now = self.scheduler.now()
        vehicles = []
        for name, pose in self.world.poses.items():
            position = pose.position(now)
            age = pose.age(now)
            spec = self.scene.vehicles.get(name)
            vehicles.append({
                "name": name,
                "source": spec.pose.source_name if spec is not None else "?",
                "position": None if position is None else [round(v, 4) for v in position],
                "age_s": None if age is None else round(age, 3),
                "stale": staleness(pose, spec, now),
                "heading": _heading(pose),
            })
        return vehicles

    def close(self) -> None:
        for link in self.links.values():
            link.close()
        self.links.clear()


def _heading(pose: Any) -> float | None:
    """The yaw (rad, from north through east: NED) a live source measured, else None (the page then
    heads a vehicle along its track)."""
    attitude = pose.attitude
    if attitude is None:
        return None
    yaw = attitude[2]
    return round(yaw, 4) if isinstance(yaw, (int, float)) and math.isfinite(yaw) else None
