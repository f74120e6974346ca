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
"""

from __future__ import annotations

import json
import logging
import math
import sys
import threading
import time
from collections import Counter, OrderedDict
from typing import Any, Callable

from .access import AccessError
from .netcodec import (MAX_TRANSMISSION, NetError, ReplayWindow, decode_pose, decode_transmission, encode_pose,
                       encode_transmission, to_local)
from .netsettle import Settlement
from ..core.inbox import Inbox
from ..gli.zenoh_auth import Identity, session_config
from ..gli.zenoh_door import WatchedPublisher, ZenohDoor
from ..sim.live_vehicle import LiveVehicle, RemoteVehicle

log = logging.getLogger(__name__)

__all__ = ["Network", "zenoh_config"]

REMEMBERED_FRAMES = 4096  # frames a control frame of another host may still refer to (S-FAMA's RTS → CTS)
JOIN_WAIT_S = 2.0
SWITCH_INTERVAL_S = 0.0002
TIME_WINDOW_S = 60.0  # another host's transmission or pose further from now than this is dropped (counted)
FIFO_DEPTH = 128
"""Transmissions Zenoh keeps for the thread that hands them to the loop (beyond that Zenoh holds back
its own reader): that thread takes them at once, and drops what the hand-over cannot hold, so this
queue stays short; at most FIFO_DEPTH × the size filter's 128 kB = 32 MB, only while the thread waits
for the GIL under a flood."""
TX_DEPTH = 2048
"""Transmissions of one host waiting for the loop (a frame's transmission is 0.1-4 kB) …"""
TX_BYTES = 4 << 20
"""… and their bytes, at most; beyond either, what the host sends is dropped until the loop has taken
some (counted ``inbox_full``, traced per host).  The hosts together: :data:`TX_TOTAL_BYTES`."""
TX_TOTAL_BYTES = 16 << 20
INBOX_DEPTH = 4096  # poses (per host) and liveliness changes waiting for the loop (each a few hundred bytes)
INBOX_BATCH = 256  # messages the loop takes from one inbox per turn (then its other inputs get a turn)


def zenoh_config(spec: Any, identity: Identity | None, connect: list[str] | tuple[str, ...] = (),
                 listen: list[str] | tuple[str, ...] = ()) -> Any:
    """The Zenoh configuration of a daemon: :func:`hilgate.gli.zenoh_auth.session_config` with the
    scene's endpoints, scouting and lease (the command line's endpoints added)."""
    return session_config(listen=list(listen or spec.listen), connect=[*spec.connect, *connect],
                          identity=identity, prefix=spec.prefix, multicast_scouting=spec.multicast_scouting,
                          lease_s=spec.lease_s, config_file=spec.config,
                          size_filter=[f"{spec.prefix}/tx/**", f"{spec.prefix}/pose/**", f"{spec.prefix}/ack/**"])


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


class Network:
    """This daemon's part of a network of daemons (see the module's docstring)."""

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
        self.heard: OrderedDict[tuple[str, int], Any] = OrderedDict()
        self.counters: Counter[str] = Counter()
        self.number = 0
        self._publishers: dict[str, Any] = {}
        self._pose_publishers: dict[str, Any] = {}
        self._tokens: dict[str, Any] = {}
        self._entities: list[Any] = []
        self._status_cache = b"{}"
        self.zid: str | None = None  # this daemon's Zenoh id, once open() joined
        self.settlement = Settlement(self)  # what became of the frames between this host and the others
        self._alives: Inbox | None = None
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

    def _alive(self, *parts: str) -> str:
        return "/".join((self.prefix, "alive", *parts))

    def _key_host(self, key: str, kind: str) -> str:
        """The host a key ``<prefix>/<kind>/<host>/…`` is under (the name Zenoh's access control vouches for)."""
        return key[len(self.prefix) + len(kind) + 2:].partition("/")[0]

    def _mine(self, scene: Any) -> set[str]:
        """The links this daemon serves (a scene that names no host is all this daemon's)."""
        return {link.id for link in scene.links.values() if link.host in (None, self.host)}

    def claim(self, scene: Any) -> None:
        """Declare this host and its links, then check nobody else claims them (both daemons of a
        race see each other and both refuse: never two daemons serving one link)."""
        liveliness = self.session.liveliness()
        self._tokens["host"] = liveliness.declare_token(self._alive(self.host, "host", self.zid))
        mine = self._mine(scene)
        for link_id in mine:
            self._tokens[link_id] = liveliness.declare_token(self._alive(self.host, "link", link_id, self.zid))
        theirs = []  # every other daemon's token, in one query (each query waits for its replies)
        for reply in liveliness.get(self._alive("**"), timeout=1.0):
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                parts = key[len(self.prefix) + 1:].split("/")
                if parts[-1] != self.zid:
                    theirs.append((parts, key))
        # (a token is under its holder's name: with credentials, only that host's daemons can hold it)
        for parts, key in theirs:
            if parts[1:3] == [self.host, "host"]:
                raise AccessError(f"host name {self.host!r} is already used by another daemon on the network "
                                  f"({key}); start this one with another --host")
        for parts, key in theirs:
            if len(parts) == 5 and parts[2] == "link" and parts[3] in mine:
                raise AccessError(f"link {parts[3]} is already served by another daemon on the network ({key})")

    def start(self, scene: Any) -> None:
        """Listen to the others and start telling them about this host (on the loop, clock running)."""
        import zenoh

        # Zenoh hands every message to a Python callback on its own threads: each needs the GIL, and
        # a busy loop would keep them waiting a whole switch interval (5 ms) per message
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        session, post = self.session, self.scheduler.post
        self.apply(scene)
        liveliness = session.liveliness()
        put = zenoh.SampleKind.PUT
        alive = self._alives = Inbox(post, self._on_alives, INBOX_DEPTH, batch=INBOX_BATCH)
        self._entities.append(liveliness.declare_subscriber(
            f"{self.prefix}/alive/**", lambda s: alive.put((str(s.key_expr), "PUT" if s.kind == put else "DELETE")),
            history=True))
        transmissions = session.declare_subscriber(f"{self.prefix}/tx/**", zenoh.handlers.FifoChannel(FIFO_DEPTH))
        self._entities.append(transmissions)
        self._listening = True
        for view in self.hosts.values():  # (what a host sent before now was not for this daemon)
            view.window.since_ns = self._listening_since()
        handover = Inbox(post, self._on_transmissions, TX_DEPTH, TX_BYTES, TX_TOTAL_BYTES, batch=INBOX_BATCH)
        threading.Thread(target=self._drain, args=(transmissions.handler, handover), name="network-tx",
                         daemon=True).start()
        poses = Inbox(post, self._on_poses, INBOX_DEPTH, batch=INBOX_BATCH)

        def on_pose(sample: Any) -> None:
            key, size = str(sample.key_expr), len(sample.payload)
            poses.put((key, sample.payload.to_bytes() if size <= MAX_TRANSMISSION else size),
                      source=self._key_host(key, "pose"))

        self._entities.append(session.declare_subscriber(f"{self.prefix}/pose/**", on_pose))
        status_key = f"{self.prefix}/status/{self.host}"  # (the answer under this host's own key: the ACL's)
        self._entities.append(session.declare_queryable(status_key, lambda q: q.reply(status_key, self._status_cache)))
        self._entities += self.settlement.start()
        world = self.router.world
        world.medium.tap = self._on_air
        self._poses_every(1.0 / self.spec.pose_rate_hz)
        self._refresh_status()

    def apply(self, scene: Any) -> None:
        """A scene (the first or a reload): which links are whose, tokens for links added or removed."""
        self.scene = scene
        mine = self._mine(scene)
        self.remote_links = {link.id: link.host for link in scene.links.values() if link.id not in mine}
        self.settlement.apply(scene, mine)
        for name in scene.hosts:
            if name != self.host and name not in self.hosts:
                self.hosts[name] = HostView(name, self._listening_since())
        liveliness = self.session.liveliness()
        for link_id in [key for key in self._tokens if key != "host" and key not in mine]:
            self._tokens.pop(link_id).undeclare()
        for link_id in mine - set(self._tokens):
            self._tokens[link_id] = liveliness.declare_token(self._alive(self.host, "link", link_id, self.zid))
        world = self.router.world
        for name, pose in world.poses.items():
            if isinstance(pose, LiveVehicle) and not isinstance(pose, RemoteVehicle) and world.local(scene.vehicles[name]):
                pose.listeners = [self._live_update(name, pose)]

    # -- liveliness ------------------------------------------------------------------------------

    def _on_alives(self, changes: list[tuple[str, str]], dropped: dict[str, int]) -> None:
        if dropped:
            self.counters["inbox_full"] += sum(dropped.values())
        for key, kind in changes:
            self._on_alive(key, kind)
        self._refresh_status()

    def _on_alive(self, key: str, kind: str) -> None:
        parts = key[len(self.prefix) + 1:].split("/")
        if len(parts) == 4 and parts[2] == "host":
            _, host, _, zid = parts
            view = self.hosts.get(host)  # (only the hosts the scene names)
            if view is None:
                return
            (view.zids.add if kind == "PUT" else view.zids.discard)(zid)
            self.settlement.alive(host, view.zids)
            up = bool(view.zids)
            if up != view.up:
                view.up = up
                if not up:
                    view.window.resync = True  # its numbers went on for the hosts that still heard it
                log.log(logging.INFO if up else logging.WARNING, "host %s is %s", host, "up" if up else "down")
                self.recorder.event({"t": round(self.scheduler.now(), 9), "ev": "host", "host": host,
                                     "state": "up" if up else "down"})
        elif len(parts) == 5 and parts[2] == "link":
            _, host, _, link, zid = parts
            view = self.hosts.get(host)
            if view is None or self.remote_links.get(link) != host:
                return  # (a host's token of a link the scene does not give it says nothing)
            zids = view.links.setdefault(link, set())
            (zids.add if kind == "PUT" else zids.discard)(zid)

    def catch_up_liveliness(self) -> None:
        """Take the liveliness changes that wait for the loop now: Zenoh may already send a host that came
        back what is published (its subscriber is matched on Zenoh's thread, its token reaches the loop
        after), and it must not be taken for down meanwhile."""
        alives = self._alives
        while alives is not None and alives.turns:  # (a batch at a time: every change waiting)
            alives._drain()

    def link_state(self, link_id: str) -> str:
        """``up``/``down`` of a link another host serves (its token is alive or not)."""
        host = self.remote_links.get(link_id)
        view = self.hosts.get(host) if host else None
        return "up" if view is not None and view.up and view.links.get(link_id) else "down"

    # -- transmissions ---------------------------------------------------------------------------

    def _remember(self, cache: OrderedDict, key: tuple[str, int], frame: Any) -> None:
        cache[key] = frame
        if len(cache) > REMEMBERED_FRAMES:
            cache.popitem(last=False)

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
        self._remember(self.sent, (frame.src_link, frame.id), frame)
        if not publisher.matching:
            self.settlement.on_air(sender, frame, None)
            return
        self.number += 1
        publisher.put(encode_transmission(self.host, self.epoch_ns, self.number, frame, t, duration,
                                          sender.pose.position(t), self.zid))
        self.counters["published"] += 1
        self.settlement.on_air(sender, frame, self.number)

    def _drain(self, handler: Any, handover: Inbox) -> None:
        """The others' transmissions, from Zenoh's queue to the loop's (``handover``: one queue per host,
        bounded in messages and bytes, taken in turns; one wake-up for all that came meanwhile, and each
        host's in its order).  What a host's queue cannot hold is dropped here, uncopied, and counted:
        this thread never waits for the loop, so Zenoh's queue stays short."""

        def copied(item: tuple[str, Any]) -> tuple[str, bytes]:
            return item[0], item[1].payload.to_bytes()

        while True:
            try:
                sample = handler.recv()  # (waits with the GIL released)
            except Exception:  # the subscriber was undeclared: the daemon is stopping
                return
            while sample is not None:
                key, size = str(sample.key_expr), len(sample.payload)
                host = self._key_host(key, "tx")
                if size <= MAX_TRANSMISSION:
                    handover.put((key, sample), size, host, copied)
                else:  # (counted on the loop, never copied; Zenoh's filter refused longer ones)
                    handover.put((key, size), 0, host)
                sample = handler.try_recv()

    def _on_transmissions(self, batch: list[tuple[str, bytes | int]], dropped: dict[str, int]) -> None:
        for host, n in dropped.items():  # what the hand-over could not hold: counted and traced per host
            self.counters["inbox_full"] += n
            self.recorder.event({"t": round(self.scheduler.now(), 9), "ev": "drop", "link": "*", "src": host,
                                 "cause": "inbox_full", "n": n})
        for key, data in batch:
            self._on_transmission(key, data)

    def _on_transmission(self, key: str, data: bytes | int) -> None:
        if isinstance(data, int):
            self.counters["bad_message"] += 1
            log.debug("a transmission of %d bytes on %s: refused unread", data, key)
            return
        try:
            message = decode_transmission(data)
        except NetError as exc:
            self.counters[exc.cause] += 1
            log.debug("unreadable transmission: %s", exc)
            return
        if message.host != self._key_host(key, "tx"):
            self.counters["forged"] += 1  # a host speaking for another (possible only without credentials)
            return
        view = self.hosts.get(message.host)
        if view is None:  # this host, or one the scene does not name: nothing of it is judged here
            if message.host != self.host:
                self.counters["foreign_sender"] += 1
            return
        frame = message.frame
        world = self.router.world
        modem = world.modems.get(frame.src_link)
        if modem is None or modem.radio.listens or self.remote_links.get(frame.src_link) != message.host:
            self.counters["foreign_sender"] += 1  # not a link the scene gives that host: ignored
            self.settlement.refused(message)
            return
        now = self.scheduler.now()
        t = to_local(message.t, message.epoch_ns, self.epoch_ns)
        # A clock that far off (or a forged time) would schedule nonsense; and no host started later than
        # now (its epoch, the UNIX clock at its model time 0, is its start: 2**62 is no start, however its
        # t makes up for it)
        if abs(now - t) > TIME_WINDOW_S or message.epoch_ns - self.epoch_ns > (now + TIME_WINDOW_S) * 1e9:
            self.counters["out_of_time"] += 1
            self.settlement.refused(message)
            return
        # Only now, the message known good in every other way, may it move the replay window (a message
        # refused above moved it before issue 37: one forged epoch made the host's every frame a replay)
        verdict = view.window.admit(message.session, message.epoch_ns, message.number, message.session in view.zids)
        if isinstance(verdict, str):
            self.counters[verdict] += 1
            self.recorder.event({"t": round(now, 9), "ev": "drop", "link": "*", "src": message.host,
                                 "cause": verdict})
            return
        if verdict:
            view.gaps += verdict
            self.recorder.event({"t": round(now, 9), "ev": "drop", "link": "*", "src": message.host,
                                 "cause": "net_gap", "n": verdict})
        if message.ref_key is not None:
            mine = self.sent.get(message.ref_key) if message.ref_key[0] not in self.remote_links else None
            frame.ref = mine or self.heard.get(message.ref_key) or frame.ref
        self._remember(self.heard, (frame.src_link, frame.id), frame)
        if not self.settlement.hear(message, modem, t, now):
            return  # (reported as never heard: its sender traced it)
        view.heard += 1
        delay = now - t
        view.delay_sum += delay
        view.delay_max = max(view.delay_max, delay)
        pose = modem.pose
        if isinstance(pose, RemoteVehicle) and message.position is not None:
            pose.update_from(t, message.position, None)
        if now > t + message.duration:
            self._account_late(modem, frame, t, message.duration, now, view)
        world.medium.transmit(modem.radio, frame, t, message.duration)

    def _account_late(self, sender: Any, frame: Any, t: float, duration: float, now: float, view: HostView) -> None:
        """Arrivals here that should have ended before the transmission was heard: delivered at once
        (the medium cannot go back), traced ``late`` and counted per host."""
        medium = self.router.world.medium
        for receiver in medium.modems:
            radio = receiver.radio
            if not radio.listens or radio.rx_channel != sender.radio.tx_channel:
                continue
            tau = medium.propagation_delay(sender.radio, radio, t)
            if tau is None:
                continue
            lateness = now - (t + tau + duration)
            if lateness > 0:
                view.late += 1
                view.late_max = max(view.late_max, lateness)
                self.recorder.event({"t": round(now, 9), "ev": "late", "link": receiver.id, "src": frame.src_link,
                                     "pkt": frame.id, "host": view.name, "lateness_s": round(lateness, 9)})

    # -- poses -----------------------------------------------------------------------------------

    def _pose_publisher(self, vehicle: str) -> Any:
        publisher = self._pose_publishers.get(vehicle)
        if publisher is None:
            import zenoh

            publisher = self._pose_publishers[vehicle] = self.session.declare_publisher(
                f"{self.prefix}/pose/{self.host}/{vehicle}", allowed_destination=zenoh.Locality.REMOTE)
        return publisher

    def _live_update(self, name: str, pose: LiveVehicle) -> Callable[[], None]:
        def published() -> None:
            now = self.scheduler.now()
            position = pose.position(now)
            age = pose.age(now)
            velocity = None
            if pose.axes and all(state.velocity is not None for state in pose.axes.values()) and len(pose.axes) == 3:
                velocity = tuple(pose.axes[a].velocity for a in ("x", "y", "z"))
            self._pose_publisher(name).put(encode_pose(self.host, self.epoch_ns, name, now - (age or 0.0),
                                                       position, velocity))

        return published

    def _poses_every(self, interval: float) -> None:
        def publish() -> None:
            now = self.scheduler.now()
            world = self.router.world
            for name, pose in world.poses.items():
                vehicle = self.scene.vehicles.get(name)
                if vehicle is None or not world.local(vehicle) or pose.static:
                    continue
                if isinstance(pose, LiveVehicle):
                    continue  # published at each measurement
                position = pose.position(now)
                earlier = pose.position(max(0.0, now - 0.01)) if position is not None else None
                velocity = None
                if earlier is not None and now > 0.01:
                    velocity = tuple((a - b) / 0.01 for a, b in zip(position, earlier))
                self._pose_publisher(name).put(encode_pose(self.host, self.epoch_ns, name, now, position, velocity))
            self._refresh_status()
            self.scheduler.after_wall(interval, publish)

        self.scheduler.after_wall(interval, publish)

    def _on_poses(self, poses: list[tuple[str, bytes | int]], dropped: dict[str, int]) -> None:
        if dropped:
            self.counters["inbox_full"] += sum(dropped.values())
        for key, data in poses:
            self._on_pose(key, data)

    def _on_pose(self, key: str, data: bytes | int) -> None:
        if isinstance(data, int):
            self.counters["bad_message"] += 1
            return
        try:
            message = decode_pose(data)
        except NetError:
            self.counters["bad_message"] += 1
            return
        if message["host"] == self.host:
            return
        if message["host"] != self._key_host(key, "pose"):
            self.counters["forged"] += 1
            return
        pose = self.router.world.poses.get(message["vehicle"])
        vehicle = self.scene.vehicles.get(message["vehicle"])
        view = self.hosts.get(message["host"])
        if vehicle is None or view is None or vehicle.host != message["host"] or message["position"] is None:
            return
        t = to_local(message["t"], message["epoch_ns"], self.epoch_ns)
        if abs(self.scheduler.now() - t) > TIME_WINDOW_S:
            self.counters["out_of_time"] += 1
            return
        if t < view.pose_t.get(message["vehicle"], -math.inf):
            self.counters["replay"] += 1  # older than one already applied: a replay, or overtaken
            return
        view.pose_t[message["vehicle"]] = t
        if isinstance(pose, RemoteVehicle):
            pose.update_from(t, message["position"], message["velocity"])
            self.router.world.medium.topology_changed()

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
        self._refresh_status()
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

    def _refresh_status(self) -> None:
        """The answer to ``status/<host>`` queries, kept ready (Zenoh asks from its own threads)."""
        local = self.router.status()
        self._status_cache = json.dumps({**self.status(), "links": local["links"],
                                         "vehicles": local["vehicles"]}, default=str).encode()

    def close(self) -> None:
        self.settlement.close(joined=self.session is not None and bool(self._entities))
        for entity in self._entities + list(self._publishers.values()) + list(self._pose_publishers.values()):
            try:
                entity.undeclare()
            except Exception:
                pass
        for token in self._tokens.values():
            try:
                token.undeclare()
            except Exception:
                pass
        self._entities, self._publishers, self._pose_publishers, self._tokens = [], {}, {}, {}
        if self.session is not None:
            try:
                self.session.close()
            except Exception:
                log.debug("closing the Zenoh session", exc_info=True)
            self.session = None

