"""Link id → backend, with the endpoints in front.

A :class:`RoutedLink` has one backend and the endpoints its doors opened (the dccomms POSIX queues, its
Unix socket and the clients on it, an emulated modem), all behind the narrow interface of
:mod:`hilgate.core.endpoint`: the router imports no endpoint class.  Endpoints live as long as the
link id is in the scene; the backend behind them may be reconfigured or replaced by a reload, which
applications do not notice except for the new behaviour.  The :class:`Router` applies scenes: the
first one builds everything, a reload changes only what :func:`hilgate.scene.diff.diff` says changed.
"""

from __future__ import annotations

import logging
import math
import random
from collections import Counter
from typing import Any, Callable

from .access import LinkLock
from .accounts import Counters, LinkAccount
from .stale_poses import staleness
from ..core.backend import AppFrame, Backend, PhyEvent
from ..core.endpoint import ABSENT, KEPT, TAKEN, Door, Endpoint
from ..core.packets import Decoded, PacketClass, packet_class
from ..drivers.bridge import ReceivingBridge, from_emulator
from ..drivers.table import DRIVERS, open_backend
from ..models.frame import BROADCAST
from ..models.link_budget import Reception, SimpleLinkBudget, reception
from ..models.usbl import UsblFix, fix as usbl_fix
from ..scene import LinkSpec, Scene
from ..scene.diff import SceneDiff, diff
from ..scene.view import link_changes, link_view as scene_view_link, scene_view, view_hash
from ..sim.sim_backend import SimBackend
from ..sim.recorder import Recorder
from ..sim.world import World

log = logging.getLogger(__name__)

UNREAD_CAUSES = ("no_reader",)


class RoutedLink:
    """One DCComms id: its backend and the endpoints in front of it.  To its endpoints it is a
    :class:`~hilgate.core.endpoint.LinkPort`; it never imports their classes."""

    def __init__(self, spec: LinkSpec, router: "Router", account: LinkAccount | None = None):
        self.router = router
        self.account = account if account is not None else LinkAccount(spec.id)
        self.spec = spec
        self.id = spec.id
        self.packet: PacketClass = packet_class(spec.packet)
        self.backend: Backend | None = None
        self.endpoints: list[Endpoint] = []
        self.doors: list[tuple[Door, Any]] = []  # (door, what it opened for this link)
        self.gli_drops: Counter[str] = Counter()
        self.seq = 0
        self.lock: LinkLock | None = None
        self.unread_kept = 0  # frames nobody took, kept in the queue for an application that starts late
        self.bridge: ReceivingBridge | None = None  # made for the first bytes an emulated modem sends here
        self._state_pending = False
        self._sole_assumer: Endpoint | None = None  # the only endpoint, if it assumes_busy (see send)
        self._usbl_rng: random.Random | None = None
        self.readdressed: int | None = None  # the address an emulated modem's AT!AL gave the link
        self.retuned: tuple[float, float] | None = None  # the band an emulated modem's channel gave the link

    # -- set-up ----------------------------------------------------------------------------------

    def open_doors(self, doors: list[Door]) -> None:
        for door in doors:
            self.doors.append((door, door.open(self)))  # (a handle of None: nothing to open yet)

    def set_backend(self, backend: Backend, kind: str | None = None) -> None:
        """Put ``backend`` (of ``kind``, the scene's name for it) behind the endpoints: the old one is
        closed first, and its period of the link's account ends with what it counted."""
        now = self.router.scheduler.now()
        first = self.backend is None
        if self.backend is not None and self.backend is not backend:
            self.backend.close()
            self.account.close(now)
        self.backend = backend
        if self.account.current is None:
            self.account.open(now, kind or self.spec.backend, self.counters, from_zero=first)
        backend.on_receive = self.deliver
        backend.on_idle = self.state_changed
        backend.on_state = lambda state: self.state_changed()
        self._tune()  # an emulated modem's channel (at power-on it came before the link had a backend)
        self._watch_phy()
        self.state_changed()

    def update(self, spec: LinkSpec, endpoints_changed: bool) -> None:
        if spec.packet != self.spec.packet:
            self._flush_bridge()
        self.spec = spec
        self.packet = packet_class(spec.packet)
        if self.readdressed is not None:  # a reload that changes the link gives it its scene address again
            old, self.readdressed = self.readdressed, None
            modem = self._sim_modem()
            if modem is not None:
                modem.set_address(spec.params.address)
            self.router.readdress(self, old, spec.params.address)
        if self.retuned is not None and self.backend is not None:
            self.backend.set_band(self.retuned)  # the emulated modem keeps its channel across reloads
        if endpoints_changed:
            self.doors = [(door, door.update(handle, self)) for door, handle in self.doors]

    # -- the port its endpoints see --------------------------------------------------------------

    @property
    def address(self) -> int:
        return self.spec.params.address if self.readdressed is None else self.readdressed

    def set_address(self, address: int) -> None:
        """An emulated modem's ``AT!AL``: the simulation uses ``address`` for this link from now on (its
        frames carry it, frames to it arrive), until a reload changes the link."""
        backend = self.backend
        if backend is None or address == self.address:
            return
        old = self.address
        if not backend.set_address(address):
            return
        self.readdressed = address
        self.router.readdress(self, old, address)
        log.info("link %s: address %d -> %d (AT!AL)", self.id, old, address)

    def set_band(self, band_khz: tuple[float, float]) -> None:
        """An emulated modem's channel (an M64's ``wcs``, or its channel at power-on): the simulation has
        this link send and listen in ``band_khz`` from now on, so that pairs on other channels never meet
        it.  At power-on the link has no backend yet (its doors open first): the band waits for it."""
        self.retuned = (float(band_khz[0]), float(band_khz[1]))
        self._tune()

    def _tune(self) -> None:
        backend = self.backend
        if backend is not None and self.retuned is not None and backend.set_band(self.retuned):
            self.router.recorder.event({"t": round(self.router.scheduler.now(), 9), "ev": "band", "link": self.id,
                                        "band_khz": list(self.retuned)})

    def withdraw(self, frames: list[AppFrame], cause: str) -> int:
        """Take these frames back from the backend's queue if they are still there (an emulated modem's
        ``ATZ``); each is traced as a drop with ``cause``."""
        backend = self.backend
        taken = backend.withdraw(frames, cause) if backend is not None else 0
        if taken:
            self.state_changed()
        return taken

    def _watch_phy(self) -> None:
        """Only while an endpoint reports the PHY (an emulated modem) does the backend report it."""
        if self.backend is not None:
            watching = any(endpoint.phy is not None for endpoint in self.endpoints)
            self.backend.watch_phy(self._phy if watching else None)

    def _phy(self, event: PhyEvent) -> None:
        for endpoint in list(self.endpoints):
            report = endpoint.phy
            if report is not None:
                report(event)

    @property
    def gli(self) -> tuple[str, ...]:
        return self.spec.gli

    @property
    def emulate(self) -> dict[str, Any]:
        return dict(self.spec.emulate)

    @property
    def limits(self) -> Any:
        """What the link's modem accepts (its ``limits:``, from its preset; None: not stated)."""
        return self.spec.limits

    @property
    def bitrate_bps(self) -> float:
        return self.spec.params.bitrate_bps

    @property
    def unet(self) -> dict[str, Any]:
        return dict(self.spec.unet)

    def address_of(self, name: str) -> int | None:
        scene = self.router.scene
        if scene is None:
            return None
        channel = self.spec.params.tx_channel
        spec = scene.links.get(name)
        if spec is None:
            mine = [s for s in scene.links.values() if s.vehicle == name and s.params.rx_channel == channel]
            spec = mine[0] if len(mine) == 1 else None
        if spec is None or spec.params.rx_channel != channel:
            return None
        other = self.router.links.get(spec.id)
        return other.address if other is not None else spec.params.address

    @property
    def ready(self) -> bool:
        backend = self.backend
        if backend is None or backend.state != "up":
            return False
        modem = backend.sim_modem  # a simulated link asks its modem itself (SimBackend.idle is its idle)
        if not (modem.idle if modem is not None else backend.idle):
            return False
        for endpoint in self.endpoints:  # (a loop, not any() over a generator: READY asks it every time)
            if endpoint.busy:
                return False
        return True

    def command(self, request: Any) -> dict[str, Any]:
        return self.router.command(self, request)

    def attach(self, endpoint: Endpoint) -> bool:
        """False when the link has as many socket clients as it may (``--max-link-clients``)."""
        if endpoint.kind == "socket" and self.clients >= self.router.max_link_clients:
            return False
        self.endpoints.append(endpoint)
        self._endpoints_changed()
        if endpoint.phy is not None:
            self._watch_phy()
        return True

    def detach(self, endpoint: Endpoint) -> None:
        if endpoint in self.endpoints:
            self.endpoints.remove(endpoint)
            self._endpoints_changed()
            if endpoint.phy is not None:
                self._watch_phy()

    def _endpoints_changed(self) -> None:
        """Which endpoint, if any, needs no BUSY after its own frame: the only one, if it says its
        applications assume BUSY once they send (``Endpoint.assumes_busy``)."""
        endpoints = self.endpoints
        sole = endpoints[0] if len(endpoints) == 1 else None
        self._sole_assumer = sole if sole is not None and sole.assumes_busy else None

    @property
    def clients(self) -> int:
        return sum(1 for endpoint in self.endpoints if endpoint.kind == "socket")

    def _sim_modem(self) -> Any:
        return self.backend.sim_modem if self.backend is not None else None

    def airtime(self, size: int) -> float | None:
        modem = self._sim_modem()
        return None if modem is None else modem.airtime(size)

    def _sender(self, address: int) -> Any:
        modem = self._sim_modem()
        if modem is None:
            return None, None
        return modem, modem.medium.modem_by_address(modem.rx_channel, address)

    def delay_from(self, address: int, t: float) -> float | None:
        mine, theirs = self._sender(address)
        # the time the frame took, whatever the range table says now (it was heard)
        return None if theirs is None else mine.medium.propagation_delay(theirs.radio, mine.radio, t, in_range=False)

    def reception_from(self, address: int, t: float) -> Reception | None:
        """What this link's modem measures of a frame from ``address`` heard at ``t`` (positions, distance,
        radial speed, RSSI, integrity: :mod:`hilgate.models.link_budget`); None if unknown."""
        mine, theirs = self._sender(address)
        if theirs is None:
            return None
        return reception(theirs.pose, mine.pose, t, SimpleLinkBudget(theirs.range_m[1]))

    def usbl_fix(self, address: int, t: float) -> tuple[Reception, UsblFix] | None:
        """The link's USBL fix of the modem at ``address`` at ``t`` (:mod:`hilgate.models.usbl`, with the
        link's noise drawn from a stream of its own, seeded by the scene); None when the link is no USBL
        or either position is unknown."""
        params = self.spec.usbl
        if params is None:
            return None
        heard = self.reception_from(address, t)
        if heard is None:
            return None
        if self._usbl_rng is None:
            seed = self.router.scene.seed if self.router.scene is not None else 0
            self._usbl_rng = random.Random(f"{seed}/{self.id}/usbl")
        return heard, usbl_fix(heard.receiver, heard.sender, params, self._usbl_rng)

    # -- application → medium --------------------------------------------------------------------

    def send_decoded(self, decoded: Decoded, sender: Endpoint | None = None) -> None:
        scheduler = self.router.scheduler
        frame = AppFrame(decoded.real, decoded.payload, self.packet, decoded.seq, self.address, decoded.dst,
                         scheduler.now())
        frame.lateness = scheduler.input_lateness
        self.send(frame, sender)

    def send_payload(self, payload: bytes, dst: int) -> None:
        real = self.packet.encode(payload, src=self.address, dst=dst)
        self.seq = (self.seq + 1) & 0xFFFFFFFF
        self.send_decoded(Decoded(real, payload, self.seq, self.address, dst))

    def send(self, frame: AppFrame, sender: Endpoint | None = None) -> None:
        """Hand a frame to the backend. A frame it cannot carry (too large for the modem) raises
        PacketError, which socket clients receive as an ERROR and queues count as a bad frame.

        Then the link's state may have changed (BUSY), and the endpoints are told at the end of the
        instant, unless nobody would be told anything (issue 31: 10 calls of every frame): the frame
        came through the link's only endpoint (``sender``), whose applications took the link as BUSY as
        they sent (``Endpoint.assumes_busy``), and the simulated modem is on air, so the link stays BUSY
        until the transmission ends, and that end tells the link itself (``on_idle``)."""
        backend = self.backend
        if backend is None:
            self.lost("no_backend", len(frame.real), src="app")
            return
        backend.admit(frame)  # PacketError: too large for the modem (its limits)
        if (isinstance(backend, SimBackend) and not backend.everyone_in_range
                and self.router.addressed_to_nobody(self.spec.params.tx_channel, frame.dst)):
            # it still goes on air (and may spoil others' frames), but nobody will ever take it
            self.lost("no_receiver", len(frame.real), ev="err", src=self.id, dst=f"addr:{frame.dst}")
        backend.send(frame)
        if sender is not None and sender is self._sole_assumer:
            modem = backend.sim_modem
            if modem is not None and modem.phy_busy and modem.on_idle is not None:
                return  # (see above: an announcement would tell its one endpoint BUSY, which it knows)
        self.state_changed()

    def lost(self, cause: str, size: int, src: str = "medium", ev: str = "drop", n: int = 1, **fields: Any) -> None:
        """A frame the GLI lost (or that nobody will take): counted by cause and traced; ``n`` frames
        lost alike at once (a flood's excess) are one trace line with ``n``."""
        self.gli_drops[cause] += n
        if n != 1:
            fields["n"] = n
        self.router.recorder.event({"t": round(self.router.scheduler.now(), 9), "ev": ev, "link": self.id,
                                    "src": src, **fields, "size": size, "cause": cause})

    # -- medium → applications -------------------------------------------------------------------

    def deliver(self, frame: AppFrame) -> None:
        """A frame the link received, to every endpoint.  One that no application at all was there to
        take is counted and traced (``no_reader``); one an application could not take is a loss of
        that application's (``app_full``, ``client_slow``)."""
        if frame.meta is not None and from_emulator(frame):
            self._from_emulator(frame)
            return
        self._hand(frame, self.endpoints)

    def _from_emulator(self, frame: AppFrame) -> None:
        """An emulated modem's bytes (an EvoLogics message, an S100's piece): this link's emulated
        modems print them as they are, its applications get the frames a bridge on the receiving side
        makes of them (:mod:`hilgate.drivers.bridge`), and bytes that make none are counted and traced."""
        t = self.router.scheduler.now()
        emulators = [endpoint for endpoint in self.endpoints if endpoint.kind == "emulator"]
        for endpoint in emulators:
            outcome = endpoint.deliver(frame, t)
            if outcome not in (TAKEN, KEPT, ABSENT):
                self.lost(outcome, len(frame.real))
        if self.bridge is None:
            self.bridge = ReceivingBridge(self.packet)
        frames, losses = self.bridge.take(frame)
        sender = self.router.link_name(self.spec.params.rx_channel, frame.src)
        for loss in losses:
            self.lost("not_a_frame", loss.size, ev="err", src=sender, reason=loss.reason)
        others = [endpoint for endpoint in self.endpoints if endpoint.kind != "emulator"]
        for whole in frames:
            self._hand(whole, others, taken=bool(emulators))
        if frame.on_delivered is not None and frame.dst == self.address:
            frame.on_delivered(frame, self)

    def _flush_bridge(self) -> None:
        """Bytes held for a frame that can no longer be completed (the link closes, its class changes)."""
        if self.bridge is not None:
            for loss in self.bridge.flush():
                self.lost("not_a_frame", loss.size, ev="err", reason=loss.reason)
            self.bridge = None

    def _hand(self, frame: AppFrame, endpoints: list[Endpoint], taken: bool = False) -> None:
        t = self.router.scheduler.now()
        kept = lost = False
        for endpoint in list(endpoints):
            outcome = endpoint.deliver(frame, t)
            if outcome == TAKEN:
                taken = True
            elif outcome == KEPT:
                kept = True
            elif outcome != ABSENT:
                lost = True
                self.lost(outcome, len(frame.real), **_pkt(frame))
        if not taken:
            if kept:
                self.unread_kept += 1  # waits in the queue for an application that starts late
            elif not lost:  # an application's own loss (app_full, client_slow) is counted once, as that
                self.lost("no_reader", len(frame.real), **_pkt(frame))
        if frame.on_delivered is not None and frame.dst == self.address:
            frame.on_delivered(frame, self)

    def state_changed(self) -> None:
        """READY/BUSY may have changed: tell the applications once the events due now have fired, so
        a frame that is sent at once goes out before a BUSY that would already be stale."""
        if not self._state_pending:
            self._state_pending = True
            self.router.scheduler.defer(self._announce_state)

    def _announce_state(self) -> None:
        self._state_pending = False
        ready = self.ready
        for endpoint in list(self.endpoints):
            endpoint.state(ready)

    # -- operations ------------------------------------------------------------------------------

    def counters(self) -> Counters:
        """What the backend and the GLI in front of it counted so far (read at the edges of a period
        of the link's account, and by ``hilgate status``; never per frame)."""
        backend = self.backend
        figures = backend.status() if backend is not None else {}
        return {"tx_packets": figures.get("tx_packets", 0), "rx_packets": figures.get("rx_packets", 0),
                "drops": figures.get("drops", 0), "unread_kept": self.unread_kept,
                "drop_causes": {cause: n for cause, n in self.gli_drops.items() if n},
                "fifo_peak_bytes": figures.get("fifo_peak_bytes")}

    def status(self) -> dict[str, Any]:
        backend = self.backend
        figures = backend.status() if backend else {"fifo_bytes": 0}
        totals = self.account.totals()  # over every backend the link has had in this run
        causes = totals["drop_causes"]
        current = self.account.current
        status = {
            "id": self.id,
            "backend": self.spec.backend,
            "state": backend.state if backend else "down",
            "tx_packets": totals["tx_packets"],
            "rx_packets": totals["rx_packets"],
            # what an application lost; a frame no application was there to read is counted apart
            "drops": totals["drops"] + sum(n for cause, n in causes.items() if cause not in UNREAD_CAUSES),
            "fifo_bytes": figures["fifo_bytes"],
            "unread": causes.get("no_reader", 0) + totals["unread_kept"],
            "drop_causes": causes,
            "clients": self.clients,
            # what the link's applications are told (READY/BUSY): false while a frame is still in the
            # modem's hands, e.g. a real modem's IM until its DELIVEREDIM or FAILEDIM
            "ready": self.ready,
            # whom a frame from an application reaches: its destination, or everyone in range where the
            # packet class carries no address on air and no MAC needs one (addressing: auto)
            "app_dst": ("everyone in range" if isinstance(backend, SimBackend) and backend.everyone_in_range
                        else "as addressed"),
            # since when the link has had this backend: model time, and the wall clock (UTC)
            "since_s": round(current.start, 6) if current is not None else None,
            "since": current.since if current is not None else None,
        }
        if figures.get("reason"):
            status["reason"] = figures["reason"]
        return status

    def close(self) -> None:
        self._flush_bridge()
        for endpoint in list(self.endpoints):
            if endpoint.kind == "socket":
                endpoint.close()
        for door, handle in self.doors:
            door.close(handle)
        self.doors = []
        self.endpoints = []
        self._endpoints_changed()
        if self.backend is not None:
            self.backend.close()
        self.account.close(self.router.scheduler.now())
        if self.lock is not None:
            self.lock.release()
            self.lock = None


def _pkt(frame: AppFrame) -> dict[str, int]:
    """The frame's id on air, for a loss's trace line, when a simulated modem delivered it."""
    return {} if frame.pkt is None else {"pkt": frame.pkt}


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
            elif isinstance(link.backend, SimBackend):
                link.backend.rebind(self.world.modems[spec.id])
                link.backend.everyone_in_range = spec.everyone_in_range
                link.backend.limits = spec.limits
                link._watch_phy()
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
