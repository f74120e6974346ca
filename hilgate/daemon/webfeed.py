"""``hilgate run --web``: the daemon's side of the web view, on its loop.

One periodic timer (``after_wall``, every ``INTERVAL_S`` of wall clock) is the whole hook into the
loop.  While no page is connected it does nothing else.  While one is, the recorder's tap feeds the
frames' events to a :class:`hilgate.web.picture.Flight` (a few dictionary operations per event), and
each tick builds a picture (links, vehicles, hosts, flows, frames in flight: plain data) and hands it
to the server's thread (:meth:`hilgate.web.server.WebServer.publish`), which never blocks.  Encoding
and writing happen on that thread, while the loop sleeps.
"""

from __future__ import annotations

import logging
from typing import Any

from ..scene.view import scene_view
from ..sim.budget import budget_tables
from ..sim.sim_backend import SimBackend
from ..web.picture import Flight, LINGER_S, extent_m, scene_message

log = logging.getLogger(__name__)

INTERVAL_S = 0.1
"""Pictures per wall-clock second: 10 (the page animates between them)."""


class WebFeed:
    """The pictures of a running daemon, for a :class:`~hilgate.web.server.WebServer`."""

    def __init__(self, scheduler: Any, router: Any, recorder: Any, server: Any, extra: Any = None):
        self.scheduler = scheduler
        self.router = router
        self.recorder = recorder
        self.server = server
        self.extra = extra  # () -> dict merged into every picture (the daemon's TCP refusals…)
        self.flight = Flight()
        self._scene: Any = None
        self._failed = False

    def start(self) -> None:
        self.scheduler.after_wall(INTERVAL_S, self._tick)

    def close(self) -> None:
        if self.recorder.tap is self:
            self.recorder.tap = None

    # -- the recorder's tap (only while a page is connected) ---------------------------------------

    def frame(self, ev: str, t: float, link: str, frame: Any, cause: str | None) -> None:
        try:  # a MAC's control frames too: the page draws them when the operator asks for them
            self.flight.frame(ev, t, link, frame.id, frame.src_link, frame.dst_link, frame.size, cause, frame.kind)
        except Exception:
            self._broken()

    def line(self, record: dict[str, Any]) -> None:
        try:
            self.flight.line(record)
        except Exception:
            self._broken()

    def _broken(self) -> None:
        """A bug here must cost the picture, never the model that called the tap."""
        if not self._failed:
            self._failed = True
            log.exception("web view: an event could not be drawn (further ones are not logged)")

    # -- the loop's timer --------------------------------------------------------------------------

    def _tick(self) -> None:
        self.scheduler.after_wall(INTERVAL_S, self._tick)
        if not self.server.clients:
            if self.recorder.tap is self:
                self.recorder.tap = None
                self.flight.clear()
            return
        if self.recorder.tap is None:
            self.recorder.tap = self
        try:
            scene = self._scene_if_changed()
            self.server.publish(scene, self.picture())
        except Exception:
            log.exception("web view: the picture could not be built")

    def _scene_if_changed(self) -> dict[str, Any] | None:
        scene = self.router.scene
        if scene is self._scene:
            return None
        self._scene = scene
        message = scene_message(scene_view(scene), "live")
        served = set(self.router.links)  # in a network of hosts, the others' links are theirs to draw
        message["served"] = sorted(served)
        try:  # the pair of modems the page hovers: SNR and PER over distance (hilgate check's budget)
            message["budget"] = budget_tables(scene)
        except Exception:
            log.exception("web view: the link budget could not be tabled (the page shows no PER)")
        self.flight.links = message["links"]
        return message

    def picture(self) -> dict[str, Any]:
        """The STATE message now: every value a fresh object (the server's thread encodes it later)."""
        router = self.router
        now = self.scheduler.now()
        links = []
        for link in router.links.values():
            status = link.status()
            backend = link.backend
            lost = dict(backend.modem.stats.lost) if isinstance(backend, SimBackend) else {}
            causes = {cause: n for cause, n in lost.items() if n}
            for cause, n in status["drop_causes"].items():
                if n:
                    causes[cause] = causes.get(cause, 0) + n
            links.append({"id": status["id"], "backend": status["backend"], "state": status["state"],
                          "ready": status["ready"], "fifo_bytes": status["fifo_bytes"],
                          "tx": status["tx_packets"], "rx": status["rx_packets"], "drops": status["drops"],
                          "lost": sum(lost.values()), "unread": status["unread"], "clients": status["clients"],
                          "drop_causes": status["drop_causes"], "since_s": status["since_s"],
                          "reason": status.get("reason"), "errors": self.flight.errors_of(status["id"]),
                          "causes": causes})
        vehicles = router.vehicle_status()
        self.flight.extent_m = extent_m(vehicle["position"] for vehicle in vehicles)
        hosts = []
        if router.network is not None:
            for remote in router.network.status()["remote_links"]:  # served by another host: its state only
                links.append({"id": remote["id"], "state": remote["state"], "host": remote["host"], "remote": True})
            for view in router.network.status()["hosts"]:
                hosts.append({"host": view["host"], "state": view["state"], "late": view["late"],
                              "late_max_ms": view["late_max_ms"], "heard": view["heard"],
                              "net_delay_mean_ms": view["net_delay_mean_ms"]})
        flows = []
        for stats in self.recorder.flows:
            lost = {cause: n for cause, n in stats.lost.items() if n}
            if stats.fifo_drops:
                lost["fifo"] = stats.fifo_drops
            flows.append({"src": stats.spec.src, "dst": stats.spec.dst, "sent": stats.tx_packets,
                          "received": stats.rx_packets, "lost": lost})
        speed = self.scheduler.speed
        picture = {"class": "STATE", "t": round(now, 6), "rate": speed, "playing": True, "speed": speed,
                   "linger_s": LINGER_S * speed, "vehicles": vehicles, "links": links, "hosts": hosts,
                   "frames": self.flight.visible(now, LINGER_S * speed, 2 * INTERVAL_S * speed), "flows": flows}
        if self.extra is not None:
            picture.update(self.extra())
        return picture
