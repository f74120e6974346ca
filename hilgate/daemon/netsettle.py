"""The daemon's side of settling frames between hosts (:mod:`.netledger` says what and why): which of a
frame's destinations are another host's, when a transmission heard here has ended at its destinations,
the reports to the others (every :data:`~.netledger.REPORT_S`, and a last one when the daemon stops), and
their reports, read on the loop.

Kept apart from :mod:`.network` and :mod:`.nethearing` (which publish and hear transmissions) so that
the settling, its keys (``<prefix>/ack/<host>/<sender>``) and its costs stay in one place: per frame for
another host, a dictionary entry on the sender and one on the receiver; per host pair, five small
messages a second.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

from .netcodec import MAX_TRANSMISSION, NetError, ReplayWindow
from .netledger import REPORT_S, Ledger, Receipts, decode_report
from ..core.inbox import Inbox
from ..models.frame import BROADCAST, DATA

log = logging.getLogger(__name__)

__all__ = ["Settlement"]

INBOX_DEPTH = 4096  # reports waiting for the loop (a few a second per host)
STOP_WAIT_S = 0.5
"""A daemon that stops waits at most this long for the others to confirm what it sent them (it is on its
way: tracing it ``unconfirmed`` at once would call lost most of what arrives)."""
REACH_S = 2.0
"""How long (model seconds) the farthest reach of a moving sender's broadcast here is taken as known."""
MOTION_MARGIN_S = 0.05
"""What is added to it meanwhile: two vehicles closing or parting at 30 m/s for REACH_S change a delay
by 40 ms at 1 500 m/s.  (Later settling costs nothing; earlier would let a daemon stopping then say it
was done with a frame still arriving.)"""


class Settlement:
    """Settling this daemon's frames with the other hosts, and theirs with them (``network``: the
    daemon's :class:`~.network.Network`, whose session, hosts, scene and counters it shares)."""

    def __init__(self, network: Any):
        self.network = network
        self.ledger = Ledger(self._lost)
        # per other host, per session heard (side by side, as the replay window keeps them: a forged session
        # beside the host's own resets nothing of it; the one heard least lately is forgotten first)
        self.receipts: dict[str, dict[str, Receipts]] = {}
        self._publishers: dict[str, Any] = {}
        self._theirs: dict[str, dict[str, tuple[str, ...]]] = {}  # channel → other host → its links there
        self._mine: dict[str, tuple[str, ...]] = {}  # channel → this host's links listening there
        self._reach: dict[str, tuple[float, float]] = {}  # sender link → (its broadcasts' longest τ here, until)
        self._reports: Inbox | None = None

    def apply(self, scene: Any, mine: set[str]) -> None:
        theirs: dict[str, dict[str, list[str]]] = {}
        local: dict[str, list[str]] = {}
        for link in scene.links.values():
            channel = link.params.rx_channel
            if link.id in mine:
                local.setdefault(channel, []).append(link.id)
            else:
                theirs.setdefault(channel, {}).setdefault(link.host, []).append(link.id)
        self._theirs = {channel: {host: tuple(links) for host, links in hosts.items()}
                        for channel, hosts in theirs.items()}
        self._mine = {channel: tuple(links) for channel, links in local.items()}
        self._reach = {}

    def start(self) -> list[Any]:
        """Listen to the others' reports and start reporting; returns the Zenoh entities to undeclare."""
        network = self.network
        reports = self._reports = Inbox(network.scheduler.post, self._on_reports, INBOX_DEPTH)

        def on_report(sample: Any) -> None:
            size = len(sample.payload)
            reports.put((str(sample.key_expr), sample.payload.to_bytes() if size <= MAX_TRANSMISSION else size))

        subscriber = network.session.declare_subscriber(f"{network.prefix}/ack/*/{network.host}", on_report)
        self._report_every(REPORT_S)
        return [subscriber]

    def alive(self, host: str, zids: set[str]) -> None:
        self.ledger.alive(host, zids)

    # -- this host's frames ----------------------------------------------------------------------

    def on_air(self, sender: Any, frame: Any, number: int | None) -> None:
        """A frame of this host went on air; ``number``: the message it went out in (None: nobody
        subscribed, so nobody heard it)."""
        if frame.app_frame is None or frame.kind != DATA:
            return
        targets = self._targets(frame, sender.tx_channel)
        if not targets:
            return
        hosts = self.network.hosts
        if number is not None and any(view is not None and not view.up for view in map(hosts.get, targets)):
            self.network.catch_up_liveliness()  # (someone heard it: the host may be back already)
        for host, links in targets.items():
            view = hosts.get(host)
            if number is not None and view is not None and view.up:
                self.ledger.published(host, number, frame.src_link, frame.id, frame.size, links)
            else:  # (it still went on air here, and to the hosts that are up)
                self.ledger.down(frame.src_link, frame.id, frame.size, links, host)

    def _targets(self, frame: Any, channel: str) -> dict[str, tuple[str, ...]] | None:
        """The other hosts' links a frame is for, by host: the one it is addressed to, or every link
        listening on its channel for a broadcast."""
        hosts = self._theirs.get(channel)
        if not hosts:
            return None
        if frame.dst_addr == BROADCAST:
            return hosts
        network = self.network
        link = network.router.link_name(channel, frame.dst_addr)
        host = network.remote_links.get(link)
        return {host: (link,)} if host is not None else None

    def _lost(self, src: str, pkt: int, size: int, dst: str, host: str, cause: str) -> None:
        """A frame of this host's link ``src`` that never reached ``dst`` on ``host``: an ``err`` of the
        sending link, counted among its drop causes."""
        network = self.network
        port = network.router.port(src)
        if port is not None:
            port.lost(cause, size, ev="err", src=src, dst=dst, pkt=pkt, host=host)
            return
        # (the link was removed meanwhile, or the daemon is stopping: its count is the network's)
        network.recorder.event({"t": round(network.scheduler.now(), 9), "ev": "err", "link": src, "src": src,
                                "dst": dst, "pkt": pkt, "host": host, "size": size, "cause": cause})

    # -- the others' frames ----------------------------------------------------------------------

    def _receipts(self, message: Any) -> Receipts:
        """The receipts of a message's session (one the replay window took: only such a message may
        start or move them), the session now the last one heard."""
        sessions = self.receipts.setdefault(message.host, {})
        receipts = sessions.pop(message.session, None)
        if receipts is None or receipts.epoch_ns != message.epoch_ns:
            receipts = Receipts(message.session, message.epoch_ns)
            if len(sessions) >= ReplayWindow.SESSIONS:
                del sessions[next(iter(sessions))]
        sessions[message.session] = receipts
        return receipts

    def refused(self, message: Any) -> None:
        """A transmission heard and refused here (counted): settled at once, if its session was heard
        already (a refused message starts nothing and pushes no session out, issue 37)."""
        receipts = self.receipts.get(message.host, {}).get(message.session)
        if receipts is not None and receipts.epoch_ns == message.epoch_ns:
            receipts.heard_one(message.number, -math.inf)

    def hear(self, message: Any, sender: Any, t: float, now: float) -> bool:
        """A transmission the replay window took, about to be handed to the medium at local time ``t``.
        False: it was already reported as never heard (its sender traced it): it must not be delivered."""
        end = max(now, self._arrivals_end(sender, message.frame, t, message.duration))
        if self._receipts(message).heard_one(message.number, end):
            return True
        self.network.counters["settled_late"] += 1
        return False

    def _arrivals_end(self, sender: Any, frame: Any, t: float, duration: float) -> float:
        """When the last arrival of a transmission at the links it is for here has ended and been
        delivered (the modem's receive delay included): from then on its outcome is in this trace.
        Exact for a frame addressed to one link; for a broadcast, the farthest of this host's listeners
        (worked out once per sender while everything is static, else every REACH_S, with a margin)."""
        channel = sender.radio.tx_channel
        if frame.dst_addr != BROADCAST:
            return t + duration + self._reach_to((self.network.router.link_name(channel, frame.dst_addr),),
                                                 sender, t)[0]
        reach = self._reach.get(sender.id)
        if reach is None or t > reach[1]:
            longest, static = self._reach_to(self._mine.get(channel, ()), sender, t)
            reach = self._reach[sender.id] = (longest, math.inf) if static else (longest + MOTION_MARGIN_S,
                                                                                t + REACH_S)
        return t + duration + reach[0]

    def _reach_to(self, links: tuple[str, ...], sender: Any, t: float) -> tuple[float, bool]:
        """The longest delay from ``sender`` at ``t`` to an arrival's delivery at ``links`` (those this
        host serves), and whether it stays so (everyone static)."""
        world = self.network.router.world
        longest, static = 0.0, sender.pose.static
        for link in links:
            receiver = world.modems.get(link)
            if receiver is None or not receiver.radio.listens:
                continue
            static = static and receiver.pose.static
            tau = world.medium.propagation_delay(sender.radio, receiver.radio, t)
            if tau is not None:
                longest = max(longest, tau + receiver.rx_delay + 6 * receiver.rx_jitter)
        return longest, static

    # -- reports ---------------------------------------------------------------------------------

    def _report_every(self, interval: float) -> None:
        scheduler = self.network.scheduler

        def report() -> None:
            self._report(final=False)
            scheduler.after_wall(interval, report)

        scheduler.after_wall(interval, report)

    def _report(self, final: bool) -> None:
        network = self.network
        now, wall = network.scheduler.now(), time.monotonic()
        for host, sessions in self.receipts.items():
            for receipts in sessions.values():
                data = receipts.report(network.host, network.zid, now, wall, final)
                if data is not None:
                    self._publisher(host).put(data)

    def _publisher(self, host: str) -> Any:
        publisher = self._publishers.get(host)
        if publisher is None:
            import zenoh

            network = self.network
            publisher = self._publishers[host] = network.session.declare_publisher(
                f"{network.prefix}/ack/{network.host}/{host}", congestion_control=zenoh.CongestionControl.DROP,
                allowed_destination=zenoh.Locality.REMOTE)
        return publisher

    def _on_reports(self, reports: list[tuple[str, bytes | int]], dropped: Any) -> None:
        network = self.network
        counters = network.counters
        if dropped:  # (a count, or a count per source)
            counters["inbox_full"] += dropped if isinstance(dropped, int) else sum(dropped.values())
        for key, data in reports:
            if isinstance(data, int):
                counters["bad_message"] += 1
                continue
            try:
                report = decode_report(data)
            except NetError as exc:
                counters[exc.cause] += 1
                continue
            host = report["host"]
            if host != network.key_host(key, "ack"):
                counters["forged"] += 1
            elif host not in network.hosts:
                counters["foreign_sender"] += 1
            elif report["session"] == network.zid and report["epoch_ns"] == network.epoch_ns:  # (not an earlier run's)
                self.ledger.report(host, report)

    # -- status and the end ----------------------------------------------------------------------

    def _await_confirmations(self) -> None:
        """Wait (at most STOP_WAIT_S) for the hosts that are up to confirm what this daemon sent them.
        The loop has stopped, so their reports are taken here, as it would have."""
        deadline = time.monotonic() + STOP_WAIT_S
        up = [host for host, view in self.network.hosts.items() if view.up]
        while self._reports is not None and self.ledger.pending(up) and time.monotonic() < deadline:
            time.sleep(REPORT_S / 10)
            self._reports._drain()  # (what the loop would have run for the reports that came meanwhile)

    def counters(self) -> dict[str, int]:
        return {cause: n for cause, n in self.ledger.counters.items() if n}

    def unsettled(self) -> int:
        return self.ledger.pending()

    def close(self, joined: bool) -> None:
        """The daemon stops (its loop has: nothing more is heard here).  ``joined``: its session is still
        open, so the others get the last word: what was on its way here will not arrive."""
        if joined:
            try:
                self._report(final=True)
            except Exception:
                log.debug("the last reports", exc_info=True)
            self._await_confirmations()
        self.ledger.close()
        for publisher in self._publishers.values():
            try:
                publisher.undeclare()
            except Exception:
                pass
        self._publishers = {}
