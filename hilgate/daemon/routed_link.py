"""One DCComms id: its backend and the endpoints its doors opened in front of it (:class:`RoutedLink`).

To its endpoints a link is a :class:`~hilgate.core.endpoint.LinkPort`; it never imports their classes.  It routes
frames (application → backend, backend → applications) and says READY/BUSY; what an emulated modem reads off
the simulation behind it is its ``measure`` (:mod:`hilgate.sim.measurements`), what a client asks about its
vehicle is :mod:`.steering`'s, and the scene's links are the :class:`~hilgate.daemon.router.Router`'s.
"""

from __future__ import annotations

import logging
from collections import Counter
from typing import TYPE_CHECKING, Any

from .access import LinkLock
from .accounts import Counters, LinkAccount
from .link_status import link_status
from ..core.backend import AppFrame, Backend, PhyEvent
from ..core.endpoint import ABSENT, KEPT, TAKEN, Door, Endpoint
from ..core.packets import Decoded, PacketClass, packet_class
from ..drivers.bridge import ReceivingBridge, from_emulator
from ..scene import LinkSpec
from ..sim.measurements import ModemMeasurements

if TYPE_CHECKING:
    from .router import Router

log = logging.getLogger(__name__)


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
        self.inbound = Inbound(self)
        self._state_pending = False
        self._sole_assumer: Endpoint | None = None  # the only endpoint, if it assumes_busy (see send)
        self.readdressed: int | None = None  # the address an emulated modem's AT!AL gave the link
        self.retuned: tuple[float, float] | None = None  # the band an emulated modem's channel gave the link
        self.measure = ModemMeasurements(spec.id, self._sim_modem, lambda: self.spec.usbl, router.scene_seed)

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
        backend.on_receive = self.inbound.deliver
        backend.on_idle = self.state_changed
        backend.on_state = lambda state: self.state_changed()
        self._tune()  # an emulated modem's channel (at power-on it came before the link had a backend)
        self._watch_phy()
        self.state_changed()

    def update(self, spec: LinkSpec, endpoints_changed: bool) -> None:
        if spec.packet != self.spec.packet:
            self.inbound.flush()
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

    def rebind(self, modem: Any) -> bool:
        """A reload changed this link in place: a simulated link's backend takes the scene's new modem, its
        addressing and its limits, and the PHY is watched anew; False when the backend is no simulated link's."""
        backend = self.backend
        if backend is None or modem is None or not backend.rebind(modem, self.spec.everyone_in_range, self.spec.limits):
            return False
        self._watch_phy()
        return True

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
        return self.router.address_of(self, name)

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
        if backend.addressed_only and self.router.addressed_to_nobody(self.spec.params.tx_channel, frame.dst):
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
        return link_status(self)

    def close(self) -> None:
        self.inbound.flush()
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


class Inbound:
    """What a link does with a frame it received (its backend's ``on_receive``): every endpoint is handed it,
    an emulated modem's bytes become frames through a bridge on the receiving side, and a frame nobody took is
    counted on the link (``no_reader``, or kept for an application that starts late)."""

    def __init__(self, link: RoutedLink):
        self.link = link
        self.bridge: ReceivingBridge | None = None  # made for the first bytes an emulated modem sends here

    def deliver(self, frame: AppFrame) -> None:
        """A frame the link received, to every endpoint.  One that no application at all was there to
        take is counted and traced (``no_reader``); one an application could not take is a loss of
        that application's (``app_full``, ``client_slow``)."""
        if frame.meta is not None and from_emulator(frame):
            self._from_emulator(frame)
            return
        self.hand(frame, self.link.endpoints)

    def _from_emulator(self, frame: AppFrame) -> None:
        """An emulated modem's bytes (an EvoLogics message, an S100's piece): this link's emulated
        modems print them as they are, its applications get the frames a bridge on the receiving side
        makes of them (:mod:`hilgate.drivers.bridge`), and bytes that make none are counted and traced."""
        t = self.link.router.scheduler.now()
        emulators = [endpoint for endpoint in self.link.endpoints if endpoint.kind == "emulator"]
        for endpoint in emulators:
            outcome = endpoint.deliver(frame, t)
            if outcome not in (TAKEN, KEPT, ABSENT):
                self.link.lost(outcome, len(frame.real))
        if self.bridge is None:
            self.bridge = ReceivingBridge(self.link.packet)
        frames, losses = self.bridge.take(frame)
        sender = self.link.router.link_name(self.link.spec.params.rx_channel, frame.src)
        for loss in losses:
            self.link.lost("not_a_frame", loss.size, ev="err", src=sender, reason=loss.reason)
        others = [endpoint for endpoint in self.link.endpoints if endpoint.kind != "emulator"]
        for whole in frames:
            self.hand(whole, others, taken=bool(emulators))
        if frame.on_delivered is not None and frame.dst == self.link.address:
            frame.on_delivered(frame, self.link)

    def flush(self) -> None:
        """Bytes held for a frame that can no longer be completed (the link closes, its class changes)."""
        if self.bridge is not None:
            for loss in self.bridge.flush():
                self.link.lost("not_a_frame", loss.size, ev="err", reason=loss.reason)
            self.bridge = None

    def hand(self, frame: AppFrame, endpoints: list[Endpoint], taken: bool = False) -> None:
        t = self.link.router.scheduler.now()
        kept = lost = False
        for endpoint in list(endpoints):
            outcome = endpoint.deliver(frame, t)
            if outcome == TAKEN:
                taken = True
            elif outcome == KEPT:
                kept = True
            elif outcome != ABSENT:
                lost = True
                self.link.lost(outcome, len(frame.real), **_pkt(frame))
        if not taken:
            if kept:
                self.link.unread_kept += 1  # waits in the queue for an application that starts late
            elif not lost:  # an application's own loss (app_full, client_slow) is counted once, as that
                self.link.lost("no_reader", len(frame.real), **_pkt(frame))
        if frame.on_delivered is not None and frame.dst == self.link.address:
            frame.on_delivered(frame, self.link)


def _pkt(frame: AppFrame) -> dict[str, int]:
    """The frame's id on air, for a loss's trace line, when a simulated modem delivered it."""
    return {} if frame.pkt is None else {"pkt": frame.pkt}
