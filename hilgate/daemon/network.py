"""Several daemons, one network: what a daemon tells the others over Zenoh and what it makes of theirs.

**Where the model runs.** Every daemon runs the medium for its own receivers.  Each transmission from
a modem this host serves is published (:mod:`.netcodec`) when it goes on air; every other host gives
it to its own medium as a transmission from that link's modem (a modem there that hears nothing and
sends only what its host says), which hands out the arrivals at *its* receivers exactly as the
sender's medium would: same start, duration and sender position, so the same delays, collisions
and error draws for its receivers.  Nothing is judged twice and no host waits for another: a host
that is cut off keeps serving its own links, and the others see its links go down (liveliness).

**Time.** A transmission's start is converted from the sender's model time to this host's through
both hosts' epochs (the UNIX clock at model time 0), so the hosts' clocks must agree (chrony on a
lab network: well under a millisecond; PTP better).  A clock offset ε shifts every arrival from that
host by ε.  When a transmission is heard after one of its arrivals here should already have ended
(the network was slower than the model's propagation delay: radio links, a loaded host), the frame
is delivered at once and the lateness is traced (``late``) and counted (``hilgate status``).

**Poses.** Each vehicle's pose is computed or measured on its host (``host:``) and published: live
vehicles at each update, scripted ones ``pose_rate_hz`` times a second; every transmission also
carries its sender's exact position.  Static vehicles are computed everywhere.

**Faults.** A daemon holds liveliness tokens for its host and each of its links; a host that dies or
is cut off loses them within the Zenoh lease (``lease_s``), its links show ``down`` here and frames
addressed to them are traced and counted ``host_down``; what was on its way when it went is settled by
the hosts' reports (:mod:`.netledger`).  A second daemon with the same host name or link is refused at start.

**Who says what.** Every key a host writes carries its name, so that Zenoh's access control (built
from the lab's credentials, :mod:`hilgate.gli.zenoh_auth`) lets each host publish, answer and hold
tokens only under its own name.  What a key's host says is then checked against the scene (a
transmission from a link the scene gives another host, a token of a link that is not its own: ignored,
counted ``foreign_sender``), against the message (a transmission whose host is not its key's:
``forged``; a time or an epoch no host can have: ``out_of_time``), and last, only once the message is
good in every other way, against what was heard before (:class:`~.netcodec.ReplayWindow`: ``replay``).

Key layout (under ``<prefix>``, ``hilgate`` unless the scene's ``zenoh.prefix`` says otherwise):
``tx/<host>/<channel>`` transmissions, ``pose/<host>/<vehicle>`` poses, ``alive/<host>/host/<zid>`` and
``alive/<host>/link/<link>/<zid>`` liveliness, ``status/<host>`` a queryable with each host's status,
``link/<host>/<id>/…`` the GLI (:mod:`hilgate.gli.zenoh_door`).

**Its parts.** This module holds the session, what the parts share (the hosts, the scene's links, the
counters) and publishes this host's transmissions; :mod:`.nethosts` keeps the other hosts' views and
liveliness, :mod:`.nethearing` takes their transmissions to the medium, :mod:`.netposes` sends and takes
poses, and :mod:`.netsettle` settles the frames between hosts.
"""

from __future__ import annotations

import json
import logging
import sys
import threading
import time
from collections import Counter, OrderedDict
from typing import Any, Callable

from .netcodec import encode_transmission
from .nethearing import Hearing, remember
from .nethosts import HostView, Liveliness
from .netposes import Poses
from .netsettle import Settlement
from ..gli.zenoh_auth import Identity, session_config
from ..gli.zenoh_door import WatchedPublisher, ZenohDoor

log = logging.getLogger(__name__)

__all__ = ["Network", "zenoh_config"]

JOIN_WAIT_S = 2.0
SWITCH_INTERVAL_S = 0.0002


def zenoh_config(spec: Any, identity: Identity | None, connect: list[str] | tuple[str, ...] = (),
                 listen: list[str] | tuple[str, ...] = ()) -> Any:
    """The Zenoh configuration of a daemon: :func:`hilgate.gli.zenoh_auth.session_config` with the
    scene's endpoints, scouting and lease (the command line's endpoints added)."""
    return session_config(listen=list(listen or spec.listen), connect=[*spec.connect, *connect],
                          identity=identity, prefix=spec.prefix, multicast_scouting=spec.multicast_scouting,
                          lease_s=spec.lease_s, config_file=spec.config,
                          size_filter=[f"{spec.prefix}/tx/**", f"{spec.prefix}/pose/**", f"{spec.prefix}/ack/**"])


class Network:
    """This daemon's part of a network of daemons (see the module's docstring): the session, what its
    parts share (the hosts, the scene's links, the counters), and this host's transmissions on air."""

    def __init__(self, scheduler: Any, router: Any, recorder: Any, host: str, spec: Any,
                 connect: list[str] | tuple[str, ...] = (), listen: list[str] | tuple[str, ...] = (),
                 clock_offset_s: float = 0.0, identity: Identity | None = None):
        self.identity = identity
        self.scheduler = scheduler
        self.router = router
        self.recorder = recorder
        self.host = host
        self.spec = spec
        self.prefix = spec.prefix
        self.connect = list(connect)
        self.listen = list(listen)
        self.clock_offset_ns = int(round(clock_offset_s * 1e9))
        self.session: Any = None
        self.hosts: dict[str, HostView] = {}
        self.remote_links: dict[str, str] = {}  # link id → host, from the scene
        self.sent: OrderedDict[tuple[str, int], Any] = OrderedDict()
        self.counters: Counter[str] = Counter()
        self.number = 0
        self._publishers: dict[str, Any] = {}
        self._entities: list[Any] = []
        self._status_cache = b"{}"
        self.zid: str | None = None  # this daemon's Zenoh id, once open() joined
        self.settlement = Settlement(self)  # what became of the frames between this host and the others
        self.liveliness = Liveliness(self)  # which hosts and links are up
        self.hearing = Hearing(self)  # the others' transmissions
        self.poses = Poses(self)  # the vehicles' poses, out and in
        self._listening = False  # (the subscriber of the others' transmissions is declared)

    # -- set-up ---------------------------------------------------------------------------------

    @property
    def epoch_ns(self) -> int:
        return self.scheduler.epoch_ns + self.clock_offset_ns

    def open(self) -> ZenohDoor:
        """Join the network; refuse (AccessError) a host name or a link another daemon serves."""
        import zenoh

        config = zenoh_config(self.spec, self.identity, self.connect, self.listen)
        self.session = session = zenoh.open(config)
        self.zid = str(session.zid())
        deadline = time.monotonic() + JOIN_WAIT_S
        wanted = len(self.connect) + len(self.spec.connect)
        while wanted and time.monotonic() < deadline and not list(session.info.peers_zid()):
            time.sleep(0.02)  # connecting to the listed peers: liveliness answers need them
        return ZenohDoor(session, self.prefix, self.host, self.scheduler.post)

    def _listening_since(self) -> int:
        """Now on the UNIX clock (ns), once this daemon hears the others' transmissions (else later than
        any start: a host's session first heard then started before this daemon heard it)."""
        return self.epoch_ns + round(self.scheduler.now() * 1e9) if self._listening else 1 << 63

    def key_host(self, key: str, kind: str) -> str:
        """The host a key ``<prefix>/<kind>/<host>/…`` is under (the name Zenoh's access control vouches for)."""
        return key[len(self.prefix) + len(kind) + 2:].partition("/")[0]

    def _mine(self, scene: Any) -> set[str]:
        """The links this daemon serves (a scene that names no host is all this daemon's)."""
        return {link.id for link in scene.links.values() if link.host in (None, self.host)}

    def claim(self, scene: Any) -> None:
        """Declare this host and its links, then refuse (AccessError) if another daemon claims them."""
        self.liveliness.claim(self._mine(scene))

    def start(self, scene: Any) -> None:
        """Listen to the others and start telling them about this host (on the loop, clock running)."""
        # Zenoh hands every message to a Python callback on its own threads: each needs the GIL, and
        # a busy loop would keep them waiting a whole switch interval (5 ms) per message
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        session = self.session
        self.apply(scene)
        self._entities.append(self.liveliness.subscribe())
        transmissions = self.hearing.subscribe()
        self._entities.append(transmissions)
        self._listening = True
        for view in self.hosts.values():  # (what a host sent before now was not for this daemon)
            view.window.since_ns = self._listening_since()
        self.hearing.hand_over(transmissions)
        self._entities.append(self.poses.subscribe())
        status_key = f"{self.prefix}/status/{self.host}"  # (the answer under this host's own key: the ACL's)
        self._entities.append(session.declare_queryable(status_key, lambda q: q.reply(status_key, self._status_cache)))
        self._entities += self.settlement.start()
        world = self.router.world
        world.medium.tap = self._on_air
        self.poses.publish_every(1.0 / self.spec.pose_rate_hz)
        self.refresh_status()

    def apply(self, scene: Any) -> None:
        """A scene (the first or a reload): which links are whose, tokens for links added or removed."""
        self.scene = scene
        mine = self._mine(scene)
        self.remote_links = {link.id: link.host for link in scene.links.values() if link.id not in mine}
        self.settlement.apply(scene, mine)
        for name in scene.hosts:
            if name != self.host and name not in self.hosts:
                self.hosts[name] = HostView(name, self._listening_since())
        self.liveliness.apply(mine)
        self.poses.apply(scene)

    # -- liveliness ------------------------------------------------------------------------------

    def catch_up_liveliness(self) -> None:
        """Take the liveliness changes that wait for the loop now (:meth:`.Liveliness.catch_up`)."""
        self.liveliness.catch_up()

    def link_state(self, link_id: str) -> str:
        """``up``/``down`` of a link another host serves (its token is alive or not)."""
        return self.liveliness.link_state(link_id)

    # -- transmissions ---------------------------------------------------------------------------

    def _on_air(self, sender: Any, frame: Any, t: float, duration: float) -> None:
        """A modem of this host transmits: tell the other hosts (if any listens)."""
        publisher = self._publishers.get(sender.tx_channel)
        if publisher is None:
            import zenoh

            # DROP, not BLOCK: a peer that hangs must never stall this loop; what Zenoh drops shows as
            # a gap in the message numbers on the receiving host (traced net_gap, counted in status).
            # Batched, not express: a put costs a sixth, and a lone message is sent at once anyway.
            # (only to other sessions: this host's own subscriber would decode each of its frames again)
            publisher = self._publishers[sender.tx_channel] = WatchedPublisher(self.session.declare_publisher(
                f"{self.prefix}/tx/{self.host}/{sender.tx_channel}", congestion_control=zenoh.CongestionControl.DROP,
                allowed_destination=zenoh.Locality.REMOTE))
        remember(self.sent, (frame.src_link, frame.id), frame)
        if not publisher.matching:
            self.settlement.on_air(sender, frame, None)
            return
        self.number += 1
        publisher.put(encode_transmission(self.host, self.epoch_ns, self.number, frame, t, duration,
                                          sender.pose.position(t), self.zid))
        self.counters["published"] += 1
        self.settlement.on_air(sender, frame, self.number)

    # -- status ----------------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        links = [{"id": link_id, "host": host, "state": self.link_state(link_id)}
                 for link_id, host in sorted(self.remote_links.items())]
        return {"host": self.host, "zid": self.zid, "epoch_ns": self.epoch_ns if self._entities else None,
                "hosts": [view.status() for _, view in sorted(self.hosts.items())], "remote_links": links,
                "counters": {**self.counters, **self.settlement.counters()}, "unsettled": self.settlement.unsettled()}

    def query_status(self, answer: Callable[[list[dict[str, Any]]], Any], timeout: float = 1.5) -> None:
        """Ask every daemon (this one too) for its status; ``answer`` gets the list on the loop.  The
        query runs on its own thread: the loop never waits for the network."""
        session, post, prefix = self.session, self.scheduler.post, self.prefix
        self.refresh_status()
        own = json.loads(self._status_cache)

        def ask() -> None:
            answers = [own]  # (a session's own queryable does not answer its own query)
            try:
                import zenoh

                for reply in session.get(f"{prefix}/status/*", timeout=timeout, target=zenoh.QueryTarget.ALL,
                                         consolidation=zenoh.ConsolidationMode.NONE):  # one answer per host
                    if reply.ok is not None:
                        try:
                            theirs = json.loads(reply.ok.payload.to_bytes())
                        except ValueError:
                            continue
                        if isinstance(theirs, dict) and theirs.get("host") != own["host"]:
                            answers.append(theirs)
            except Exception as exc:  # the session closed meanwhile
                log.debug("network status query: %s", exc)
            post(answer, sorted(answers, key=lambda a: str(a.get("host"))))

        threading.Thread(target=ask, name="network-status", daemon=True).start()

    def refresh_status(self) -> None:
        """The answer to ``status/<host>`` queries, kept ready (Zenoh asks from its own threads)."""
        local = self.router.status()
        self._status_cache = json.dumps({**self.status(), "links": local["links"],
                                         "vehicles": local["vehicles"]}, default=str).encode()

    def close(self) -> None:
        self.settlement.close(joined=self.session is not None and bool(self._entities))
        for entity in self._entities + list(self._publishers.values()) + list(self.poses.publishers.values()):
            try:
                entity.undeclare()
            except Exception:
                pass
        self.liveliness.close()
        self._entities, self._publishers, self.poses.publishers = [], {}, {}
        if self.session is not None:
            try:
                self.session.close()
            except Exception:
                log.debug("closing the Zenoh session", exc_info=True)
            self.session = None

