"""What a daemon knows of the other hosts of its network: each one's view (:class:`HostView`), and whether
it and its links are up, from the liveliness tokens every daemon holds for its host and each of its links.

Kept apart from :mod:`.network` and :mod:`.nethearing` (which publish and hear transmissions) so that
the tokens, their keys (``alive/<host>/host/<zid>`` and ``alive/<host>/link/<link>/<zid>``) and the
refusal of a second daemon with the same host name or link stay in one place.
"""

from __future__ import annotations

import logging
from typing import Any

from .access import AccessError
from .netcodec import ReplayWindow
from ..core.inbox import Inbox

log = logging.getLogger(__name__)

__all__ = ["HostView", "Liveliness"]

INBOX_DEPTH = 4096  # liveliness changes waiting for the loop (each a few hundred bytes)
INBOX_BATCH = 256  # changes the loop takes per turn (then its other inputs get a turn)


class HostView:
    """What this daemon knows of another host."""

    __slots__ = ("name", "up", "zids", "links", "heard", "gaps", "late", "late_max", "delay_sum", "delay_max",
                 "window", "pose_t")

    def __init__(self, name: str, since_ns: int = 0):
        self.name = name
        self.zids: set[str] = set()
        self.up = False
        self.links: dict[str, set[str]] = {}
        self.heard = 0
        self.gaps = 0
        self.late = 0
        self.late_max = 0.0
        self.delay_sum = 0.0
        self.delay_max = 0.0
        self.window = ReplayWindow(since_ns)  # (since_ns: when this daemon began to hear that host)
        self.pose_t: dict[str, float] = {}  # vehicle → the measurement time of its latest pose

    def status(self) -> dict[str, Any]:
        return {"host": self.name, "state": "up" if self.up else "down",
                "links": sorted(link for link, zids in self.links.items() if zids),
                "heard": self.heard, "gaps": self.gaps, "late": self.late,
                "late_max_ms": round(self.late_max * 1e3, 3),
                "net_delay_mean_ms": round(self.delay_sum / self.heard * 1e3, 3) if self.heard else None,
                "net_delay_max_ms": round(self.delay_max * 1e3, 3)}


class Liveliness:
    """This daemon's tokens and the others' (``network``: the daemon's :class:`~.network.Network`, whose
    session, hosts, scene and counters it shares)."""

    def __init__(self, network: Any):
        self.network = network
        self._tokens: dict[str, Any] = {}
        self._alives: Inbox | None = None

    def _alive(self, *parts: str) -> str:
        return "/".join((self.network.prefix, "alive", *parts))

    def claim(self, mine: set[str]) -> None:
        """Declare this host and its links (``mine``), then check nobody else claims them (both daemons
        of a race see each other and both refuse: never two daemons serving one link)."""
        network = self.network
        liveliness = network.session.liveliness()
        self._tokens["host"] = liveliness.declare_token(self._alive(network.host, "host", network.zid))
        for link_id in mine:
            self._tokens[link_id] = liveliness.declare_token(self._alive(network.host, "link", link_id, network.zid))
        theirs = []  # every other daemon's token, in one query (each query waits for its replies)
        for reply in liveliness.get(self._alive("**"), timeout=1.0):
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                parts = key[len(network.prefix) + 1:].split("/")
                if parts[-1] != network.zid:
                    theirs.append((parts, key))
        # (a token is under its holder's name: with credentials, only that host's daemons can hold it)
        for parts, key in theirs:
            if parts[1:3] == [network.host, "host"]:
                raise AccessError(f"host name {network.host!r} is already used by another daemon on the network "
                                  f"({key}); start this one with another --host")
        for parts, key in theirs:
            if len(parts) == 5 and parts[2] == "link" and parts[3] in mine:
                raise AccessError(f"link {parts[3]} is already served by another daemon on the network ({key})")

    def apply(self, mine: set[str]) -> None:
        """Tokens for the links of this host a scene added, none for those it removed."""
        network = self.network
        liveliness = network.session.liveliness()
        for link_id in [key for key in self._tokens if key != "host" and key not in mine]:
            self._tokens.pop(link_id).undeclare()
        for link_id in mine - set(self._tokens):
            self._tokens[link_id] = liveliness.declare_token(self._alive(network.host, "link", link_id, network.zid))

    def subscribe(self) -> Any:
        """Hear the others' tokens come and go (those already held first); returns the subscriber."""
        import zenoh

        network = self.network
        put = zenoh.SampleKind.PUT
        alive = self._alives = Inbox(network.scheduler.post, self._on_alives, INBOX_DEPTH, batch=INBOX_BATCH)
        return network.session.liveliness().declare_subscriber(
            f"{network.prefix}/alive/**", lambda s: alive.put((str(s.key_expr), "PUT" if s.kind == put else "DELETE")),
            history=True)

    def _on_alives(self, changes: list[tuple[str, str]], dropped: dict[str, int]) -> None:
        if dropped:
            self.network.counters["inbox_full"] += sum(dropped.values())
        for key, kind in changes:
            self._on_alive(key, kind)
        self.network.refresh_status()

    def _on_alive(self, key: str, kind: str) -> None:
        network = self.network
        parts = key[len(network.prefix) + 1:].split("/")
        if len(parts) == 4 and parts[2] == "host":
            _, host, _, zid = parts
            view = network.hosts.get(host)  # (only the hosts the scene names)
            if view is None:
                return
            (view.zids.add if kind == "PUT" else view.zids.discard)(zid)
            network.settlement.alive(host, view.zids)
            up = bool(view.zids)
            if up != view.up:
                view.up = up
                if not up:
                    view.window.resync = True  # its numbers went on for the hosts that still heard it
                log.log(logging.INFO if up else logging.WARNING, "host %s is %s", host, "up" if up else "down")
                network.recorder.event({"t": round(network.scheduler.now(), 9), "ev": "host", "host": host,
                                        "state": "up" if up else "down"})
        elif len(parts) == 5 and parts[2] == "link":
            _, host, _, link, zid = parts
            view = network.hosts.get(host)
            if view is None or network.remote_links.get(link) != host:
                return  # (a host's token of a link the scene does not give it says nothing)
            zids = view.links.setdefault(link, set())
            (zids.add if kind == "PUT" else zids.discard)(zid)

    def catch_up(self) -> None:
        """Take the liveliness changes that wait for the loop now: Zenoh may already send a host that came
        back what is published (its subscriber is matched on Zenoh's thread, its token reaches the loop
        after), and it must not be taken for down meanwhile."""
        alives = self._alives
        while alives is not None and alives.turns:  # (a batch at a time: every change waiting)
            alives._drain()

    def link_state(self, link_id: str) -> str:
        """``up``/``down`` of a link another host serves (its token is alive or not)."""
        network = self.network
        host = network.remote_links.get(link_id)
        view = network.hosts.get(host) if host else None
        return "up" if view is not None and view.up and view.links.get(link_id) else "down"

    def close(self) -> None:
        for token in self._tokens.values():
            try:
                token.undeclare()
            except Exception:
                pass
        self._tokens = {}
