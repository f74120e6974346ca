"""Link id → backend, with the GLI endpoints in front.

A :class:`Link` owns its endpoints (the dccomms POSIX queues, its Unix socket, the socket clients
attached to it) and one backend.  Endpoints live as long as the link id is in the scene; the backend
behind them may be reconfigured or replaced by a reload, which applications do not notice except
for the new behaviour.  The :class:`Router` applies scenes: the first one builds everything, a
reload changes only what differs.
"""

from __future__ import annotations

import logging
import math
import os
from collections import Counter
from typing import Any, Callable

from .access import LinkLock
from ..core.backend import AppFrame, Backend
from ..sim.backend import SimBackend
from ..gli.queues import MqEndpoint, plan_message_size
from ..gli.sockets import GliClient, refuse_client
from ..models.frame import BROADCAST
from ..core.packets import Decoded, PacketClass, PacketError, packet_class
from ..sim.recorder import Recorder
from ..scene import LinkSpec, Scene
from ..core.streams import Listener, listen_unix
from ..sim.world import World

log = logging.getLogger(__name__)

UNREAD_CAUSES = ("no_reader",)


class Link:
    def __init__(self, spec: LinkSpec, router: "Router"):
        self.router = router
        self.spec = spec
        self.id = spec.id
        self.packet: PacketClass = packet_class(spec.packet)
        self.backend: Backend | None = None
        self.clients: set[GliClient] = set()
        self.gli_drops: Counter[str] = Counter()
        self.seq = 0
        self.mq: MqEndpoint | None = None
        self.listener: Listener | None = None
        self.emulator: Any = None
        self.lock: LinkLock | None = None
        self.unread_kept = 0  # frames nobody took, kept in the queue for an application that starts late
        self._state_pending = False

    # -- set-up ----------------------------------------------------------------------------------

    def open_endpoints(self, scheduler: Any, socket_dir: str | None, full_size_queues: bool = True) -> None:
        self.mq = MqEndpoint(self.id, self.packet, scheduler, self.from_mq, self.bad_frame, lambda: self.ready,
                             full_size_queues, self.router.gli_backlog, self.router.group, self._stale)
        if socket_dir is not None:
            path = os.path.join(socket_dir, f"{self.id}.sock")
            self.listener = Listener(listen_unix(path, group=self.router.group), scheduler,
                                     lambda sock: self.router.accept_client(sock, self.id), path)
        self.open_emulator(scheduler)

    def _stale(self, origin: str, size: int) -> None:
        """A frame left in a queue while no daemon ran: never sent, counted and traced."""
        self._lost("stale", size, src=origin)

    def open_emulator(self, scheduler: Any) -> None:
        """An emulated EvoLogics/S100 device in front of this (simulated) link, if the scene asks."""
        if self.emulator is not None:
            self.emulator.close()
            self.emulator = None
        if self.spec.emulate:
            from ..drivers.emulators import EMULATORS

            options = dict(self.spec.emulate)
            self.emulator = EMULATORS[options["protocol"]](self, options, scheduler)

    def sim_modem(self) -> Any:
        """The simulated modem behind this link, or None when a real modem drives it."""
        backend = self.backend
        return getattr(backend, "modem", None)

    def set_backend(self, backend: Backend) -> None:
        if self.backend is not None and self.backend is not backend:
            self.backend.close()
        self.backend = backend
        backend.on_receive = self.to_apps
        backend.on_idle = self.state_changed
        backend.on_state = lambda state: self.state_changed()
        self.state_changed()

    def update(self, spec: LinkSpec) -> None:
        emulate_changed = spec.emulate != self.spec.emulate
        self.spec = spec
        if emulate_changed:
            self.open_emulator(self.router.scheduler)
        if spec.packet != self.packet.name:
            self.packet = packet_class(spec.packet)
            if self.mq is not None:
                self.mq.packet = self.packet

    @property
    def address(self) -> int:
        return self.spec.params.address

    @property
    def ready(self) -> bool:
        backend = self.backend
        return (backend is not None and backend.state == "up" and backend.idle
                and not (self.emulator is not None and self.emulator.busy))

    def welcome(self) -> dict[str, Any]:
        from ..gli.wire import VERSION

        return {"link": self.id, "address": self.address, "packet": self.packet.name,
                "max_payload": self.packet.max_payload, "version": VERSION}

    # -- application → medium --------------------------------------------------------------------

    def from_mq(self, decoded: Decoded) -> None:
        try:
            self._send(decoded.real, decoded.payload, decoded.seq, decoded.dst)
        except PacketError as exc:
            log.warning("link %s: %s", self.id, exc)
            self.bad_frame(exc.reason, len(decoded.real))

    def from_client(self, payload: bytes, dst: int) -> None:
        real = self.packet.encode(payload, src=self.address, dst=dst)
        self.seq = (self.seq + 1) & 0xFFFFFFFF
        self._send(real, payload, self.seq, dst)

    def _send(self, real: bytes, payload: bytes, seq: int, dst: int) -> None:
        scheduler = self.router.scheduler
        frame = AppFrame(real, payload, self.packet, seq, self.address, dst, scheduler.now())
        frame.lateness = getattr(scheduler, "input_lateness", 0.0)
        self.send_frame(frame)

    def send_frame(self, frame: AppFrame) -> None:
        """Hand a frame to the backend. A frame it cannot carry (too large for the modem) raises
        PacketError, which socket clients receive as an ERROR and queues count as a bad frame."""
        backend = self.backend
        if backend is None:
            self.bad_frame("no_backend", len(frame.real))
            return
        if (isinstance(backend, SimBackend) and not backend.everyone_in_range
                and self.router.addressed_to_nobody(self.spec.params.tx_channel, frame.dst)):
            # it still goes on air (and may spoil others' frames), but nobody will ever take it
            self._lost("no_receiver", len(frame.real), ev="err", src=self.id, dst=f"addr:{frame.dst}")
        backend.send(frame)
        self.state_changed()

    def bad_frame(self, reason: str, size: int) -> None:
        """A frame from an application that could not be accepted: counted and traced, then dropped."""
        log.debug("link %s: dropped a frame from an application (%s, %d bytes)", self.id, reason, size)
        self._lost(reason, size, src="app")

    # -- medium → applications -------------------------------------------------------------------

    def to_apps(self, frame: AppFrame) -> None:
        """A frame the link received: to the queue application, every socket client, the emulator.
        A frame that no application at all was there to take is counted and traced (``no_reader``);
        one that an application could not take is a drop of that application's (``app_full``)."""
        t = self.router.scheduler.now()
        taken = False
        outcome = None
        if self.mq is not None:
            real = frame.real
            if frame.packet.name != self.packet.name:
                try:
                    real = self.packet.encode(frame.payload, src=frame.src, dst=frame.dst)
                except PacketError:
                    real = None
                    self._lost("size", len(frame.real))
            if real is not None:
                outcome = self.mq.deliver(real, frame.seq, frame.src, frame.dst)
                if outcome == "queued":
                    taken = True
                elif outcome == "app_full":
                    self._lost("app_full", len(frame.real))
        for client in list(self.clients):
            if client.deliver(frame.src, frame.dst, t, frame.payload):
                taken = True
            else:  # it stopped reading: past its output cap it is disconnected
                self._lost("client_slow", len(frame.real))
        if self.emulator is not None:
            self.emulator.deliver(frame, t)
            taken = True
        if not taken and outcome != "app_full":  # no application at all took it
            if outcome == "kept":
                self.unread_kept += 1  # waits in the queue for an application that starts late
            else:
                self._lost("no_reader", len(frame.real))
        if frame.on_delivered is not None and frame.dst == self.address:
            frame.on_delivered(frame, self)

    def _lost(self, cause: str, size: int, ev: str = "drop", src: str = "medium", **fields: Any) -> None:
        """A frame the GLI lost (or that nobody will take): counted by cause and traced."""
        self.gli_drops[cause] += 1
        self.router.recorder.event({"t": round(self.router.scheduler.now(), 9), "ev": ev, "link": self.id,
                                    "src": src, **fields, "size": size, "cause": cause})

    def state_changed(self) -> None:
        """READY/BUSY may have changed: tell the applications once the events due now have fired, so
        a frame that is sent at once goes out before a BUSY that would already be stale."""
        if not self._state_pending:
            self._state_pending = True
            self.router.scheduler.defer(self._announce_state)

    def _announce_state(self) -> None:
        self._state_pending = False
        ready = self.ready
        if self.mq is not None:
            self.mq.state_changed()
        for client in list(self.clients):
            client.state(ready)

    def attach_client(self, client: GliClient) -> bool:
        """False when the link has as many socket clients as it may (``--max-link-clients``)."""
        if len(self.clients) >= self.router.max_link_clients:
            return False
        self.clients.add(client)
        return True

    def detach_client(self, client: GliClient) -> None:
        self.clients.discard(client)

    # -- operations ------------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        backend = self.backend
        figures = backend.status() if backend else {"tx_packets": 0, "rx_packets": 0, "drops": 0, "fifo_bytes": 0}
        causes = {cause: n for cause, n in self.gli_drops.items() if n}
        status = {
            "id": self.id,
            "backend": self.spec.backend,
            "state": backend.state if backend else "down",
            "tx_packets": figures["tx_packets"],
            "rx_packets": figures["rx_packets"],
            # what an application lost; a frame no application was there to read is counted apart
            "drops": figures["drops"] + sum(n for cause, n in causes.items() if cause not in UNREAD_CAUSES),
            "fifo_bytes": figures["fifo_bytes"],
            "unread": causes.get("no_reader", 0) + self.unread_kept,
            "drop_causes": causes,
            "clients": len(self.clients),
        }
        if figures.get("reason"):
            status["reason"] = figures["reason"]
        return status

    def close(self) -> None:
        for client in list(self.clients):
            client.close()
        if self.emulator is not None:
            self.emulator.close()
        if self.listener is not None:
            self.listener.close()
        if self.mq is not None:
            self.mq.close()
        if self.backend is not None:
            self.backend.close()
        if self.lock is not None:
            self.lock.release()
            self.lock = None


class Router:
    def __init__(self, scheduler: Any, recorder: Recorder, socket_dir: str | None = None, gli_backlog: int = 1000,
                 group: int | None = None, max_clients: int = 256, max_link_clients: int = 32,
                 client_output_cap: int = 256 * 1024):
        self.scheduler = scheduler
        self.gli_backlog = gli_backlog
        self.recorder = recorder
        self.socket_dir = socket_dir
        self.links: dict[str, Link] = {}
        self.world: World | None = None
        self.scene: Scene | None = None
        self._names: dict[tuple[str, int], str] = {}
        self.backend_factories: dict[str, Callable[[LinkSpec], Backend]] = {
            "sim": self._sim_backend, "evologics": self._driver_backend, "s100": self._driver_backend}
        self.full_size_queues: bool | None = None
        self.group = group
        self.max_clients = max_clients
        self.max_link_clients = max_link_clients
        self.client_output_cap = client_output_cap
        self.clients: set[GliClient] = set()  # every socket client, on a link or not yet (TCP before HELLO)
        if socket_dir is not None:
            os.makedirs(socket_dir, mode=0o750, exist_ok=True)

    def accept_client(self, sock: Any, link_id: str | None = None) -> None:
        """A new socket client (on a link's Unix socket, or on the TCP listener before its HELLO),
        unless the daemon has as many as it may: then it is told why and closed."""
        if len(self.clients) >= self.max_clients:
            log.info("GLI client refused: %d clients already (--max-clients)", len(self.clients))
            refuse_client(sock, f"too many clients ({self.max_clients})")
            return
        client = GliClient(sock, self.scheduler, self, link_id, self.client_output_cap)
        if not client.connection.closed:  # refused at once (no such link, too many on it): gone already
            self.clients.add(client)

    def link_name(self, channel: str, address: int) -> str:
        return self._names.get((channel, address), f"addr:{address}")

    def _sim_backend(self, spec: LinkSpec) -> Backend:
        assert self.world is not None
        return SimBackend(self.world.modems[spec.id], self.link_name, spec.everyone_in_range)

    def addressed_to_nobody(self, channel: str, address: int) -> bool:
        return address != BROADCAST and (channel, address) not in self._names

    def _driver_backend(self, spec: LinkSpec) -> Backend:
        from ..drivers.evologics import EvologicsBackend, EvologicsOptions
        from ..drivers.s100 import S100Backend, S100Options

        options = dict(spec.options)
        packet = packet_class(spec.packet)
        if spec.backend == "evologics":
            return EvologicsBackend(spec.id, spec.params.address, packet, EvologicsOptions(**options),
                                    self.scheduler, self.recorder.event)
        options.setdefault("air_bitrate_bps", spec.params.bitrate_bps)
        return S100Backend(spec.id, spec.params.address, packet, S100Options(**options), self.scheduler,
                           self.recorder.event)

    def apply(self, scene: Scene) -> None:
        """Build the first scene, or change the running one into ``scene`` (already validated)."""
        self._names = {(l.params.rx_channel, l.params.address): l.id for l in scene.links.values()}
        self._names.update({(l.params.rx_channel, BROADCAST): "*" for l in scene.links.values()})
        first = self.world is None
        if first:
            self.full_size_queues = plan_message_size(
                len(scene.links), [1 + packet_class(l.packet).body_size for l in scene.links.values()])
            self.world = World(scene, self.scheduler, self.recorder)
        else:
            self.world.reconfigure(scene)
        old = self.scene
        self.scene = scene
        for link_id in [i for i in self.links if i not in scene.links]:
            log.info("link %s removed", link_id)
            self.links.pop(link_id).close()
        for spec in scene.links.values():
            link = self.links.get(spec.id)
            if link is None:
                lock = LinkLock(spec.id)  # one daemon per link id on this host, or refused here
                link = Link(spec, self)
                link.lock = lock
                try:
                    link.open_endpoints(self.scheduler, self.socket_dir, bool(self.full_size_queues))
                except BaseException:
                    link.close()
                    raise
                self.links[spec.id] = link
                link.set_backend(self.backend_factories[spec.backend](spec))
                if link.mq is not None:
                    link.mq.start()
                if not first:
                    log.info("link %s added (%s)", spec.id, spec.backend)
                continue
            before = old.links[spec.id] if old else None
            link.update(spec)
            if before is not None and (before.backend != spec.backend or
                                       (spec.backend != "sim" and before.options != spec.options)):
                log.info("link %s: backend %s -> %s", spec.id, before.backend, spec.backend)
                link.set_backend(self.backend_factories[spec.backend](spec))
            elif isinstance(link.backend, SimBackend):
                link.backend.rebind(self.world.modems[spec.id])
                link.backend.everyone_in_range = spec.everyone_in_range
                if before != spec:
                    log.info("link %s reconfigured", spec.id)
            link.state_changed()
        if first:
            self.world.start()

    def command(self, link: Link, request: Any) -> dict[str, Any]:
        """A client's request about its link or its vehicle:

        - ``{"class": "STATUS"}``: the link's status;
        - ``{"class": "POSE"}``: the vehicle's position now;
        - ``{"class": "GOTO", "position": [x, y, z]}``, ``{"class": "VELOCITY", "velocity": [vx, vy, vz]}``,
          ``{"class": "STOP"}``: steer a ``controlled`` vehicle (at most at its maximum speed)."""
        from ..models.controlled import Controlled

        if not isinstance(request, dict):
            return {"class": "ERROR", "error": "a request is a JSON object with a class"}
        kind = request.get("class")
        now = self.scheduler.now()
        if kind == "STATUS":
            return {"class": "STATUS", "link": link.status()}
        pose = self.world.poses.get(link.spec.vehicle) if self.world else None
        if kind == "POSE":
            position = pose.position(now) if pose is not None else None
            return {"class": "POSE", "vehicle": link.spec.vehicle, "t": round(now, 6),
                    "position": None if position is None else [round(v, 6) for v in position]}
        if kind in ("GOTO", "VELOCITY", "STOP"):
            if not isinstance(pose, Controlled):
                return {"class": "ERROR", "error": f"vehicle {link.spec.vehicle!r} is not controlled by applications"}
            try:
                if kind == "STOP":
                    pose.stop(now)
                else:
                    key = "position" if kind == "GOTO" else "velocity"
                    values = tuple(float(v) for v in request[key])
                    if len(values) != 3 or not all(map(math.isfinite, values)):
                        raise ValueError
                    (pose.go_to if kind == "GOTO" else pose.set_velocity)(now, values)
            except (KeyError, TypeError, ValueError):
                return {"class": "ERROR", "error": f"{kind} needs {'position' if kind == 'GOTO' else 'velocity'}: "
                                                   "a list of three numbers"}
            self.world.medium.topology_changed()
            return {"class": kind, "ok": True, "t": round(now, 6)}
        return {"class": "ERROR", "error": f"unknown request {kind!r}"}

    def status(self) -> dict[str, Any]:
        assert self.world is not None and self.scene is not None
        now = self.scheduler.now()
        vehicles = []
        for name, pose in self.world.poses.items():
            position = pose.position(now)
            age = getattr(pose, "age", lambda t: 0.0)(now)
            vehicles.append({
                "name": name,
                "source": self.scene.vehicles[name].pose.source_name,
                "position": None if position is None else [round(v, 4) for v in position],
                "age_s": None if age is None else round(age, 3),
            })
        return {"links": [link.status() for link in self.links.values()], "vehicles": vehicles}

    def close(self) -> None:
        for link in self.links.values():
            link.close()
        self.links.clear()
