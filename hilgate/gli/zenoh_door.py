"""The GLI over Zenoh: an application anywhere on the network reaches a link by id.

The serving daemon (host ``<host>``) declares, for each of its links, under ``<prefix>/link/<host>/<id>/``:

==================  ==============  ==================================================================
key                 who puts        payload
==================  ==============  ==================================================================
``send/<client>``   application     ``u8 dst`` (255 broadcast) then the payload
``recv``            daemon          ``u8 src | u8 dst | f64 model time (big-endian)`` then the payload
``state``           daemon          ``u8``: 1 READY, 0 BUSY (when it changes)
``error/<client>``  daemon          UTF-8 JSON ``{"error": "..."}`` for a frame that client sent
``info``            queryable       UTF-8 JSON ``{"link", "address", "packet", "max_payload", "version",
                                    "ready", "host"}`` (the socket GLI's WELCOME, plus READY and host)
``command/<client>`` queryable      query payload: a JSON request as the socket GLI's COMMAND; reply:
                                    its answer
==================  ==============  ==================================================================

These are the bodies of the socket GLI's SEND, RECV and STATE messages (:mod:`hilgate.gli.wire`),
so an application in C, C++ or Rust needs a Zenoh session and ``struct`` packing, nothing of hilgate.
``<client>`` is the application's name: with the lab's credentials, the name its certificate proves
(Zenoh's access control lets it put only under that name, :mod:`hilgate.gli.zenoh_auth`); without,
whatever it says.  An application finds the host of a link by asking ``<prefix>/link/*/<id>/info``.

**Bounded per client.** Zenoh calls back on its own threads; nothing there waits for the loop.  Each
client has its own queue of SENDs at the door (:data:`CLIENT_QUEUE`) filled at most at
:data:`CLIENT_RATE_HZ` on average (a token bucket of :data:`CLIENT_BURST`); the loop takes them in turn,
one per client per turn, whenever the link is READY (the turns kept from one READY to the next), so
one client's flood fills only its own queue: its excess is dropped and counted (``rate``,
``client_queue``) while the others' frames go through at their own pace (:class:`SenderQueues`).
A command query is answered from the loop, at most :data:`QUERY_PENDING` of a client at a time and
:data:`QUERY_RATE_HZ` on average; one beyond is dropped unanswered (counted ``query_refused``).  What
the door holds in all is bounded: :data:`MAX_CLIENTS` per link (a newcomer takes the place of a
client over its share), :data:`DOOR_BYTES` of SENDs.
"""

from __future__ import annotations

import json
import logging
import re
import struct
import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from typing import Any

from ..core import safejson
from ..core.backend import AppFrame
from ..core.endpoint import ABSENT, TAKEN, LinkPort
from ..core.packets import PacketError
from . import wire

log = logging.getLogger(__name__)

__all__ = ["WatchedPublisher", "ZenohDoor", "ZenohEndpoint", "link_key", "CLIENT_NAME"]

_RECV = struct.Struct(">BBd")
CLIENT_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")
CLIENT_QUEUE = 64          # SENDs of one client waiting at the door for the link to be READY
CLIENT_RATE_HZ = 1000.0    # SENDs per second a client may make on average …
CLIENT_BURST = 200         # … and at once
MAX_SEND = 1 + 65536       # a SEND longer than this is refused unread (no packet class carries more)
MAX_CLIENTS = 32           # clients a link's door keeps queues for (then one over its share gives its place up)
DOOR_BYTES = 16 << 20      # bytes of SENDs all links' doors hold in all
QUERY_PENDING = 4          # command queries of one client waiting for the loop
QUERY_RATE_HZ = 50.0       # command and info queries per second a client (info: a link) may make …
QUERY_BURST = 20           # … and at once
MAX_REQUEST = 65536        # bytes of a command's JSON


def link_key(prefix: str, host: str, link_id: str, leaf: str) -> str:
    return f"{prefix}/link/{host}/{link_id}/{leaf}"


class WatchedPublisher:
    """A Zenoh publisher and whether anybody subscribes to it (``matching``), kept up to date by Zenoh
    (a matching listener) rather than asked before every message: asking costs about 2 µs, a frame's
    whole pass through the daemon about 40."""

    __slots__ = ("publisher", "matching", "_listener")

    def __init__(self, publisher: Any):
        self.publisher = publisher
        self.matching = False
        self._listener = publisher.declare_matching_listener(self._changed)
        # (read after the listener exists: no change is missed; the status, not the object, which is
        # always true: every frame was sent to nobody, 6 µs of the loop's each)
        self.matching = publisher.matching_status.matching

    def _changed(self, status: Any) -> None:  # (on a Zenoh thread; a bool is set in one step)
        self.matching = status.matching

    def put(self, payload: bytes) -> None:
        self.publisher.put(payload)

    def undeclare(self) -> None:
        for entity in (self._listener, self.publisher):
            try:
                entity.undeclare()
            except Exception:  # the session is closing: already gone
                pass


class Bucket:
    """A token bucket: ``take`` is True while the average rate stays under ``rate`` (``burst`` at once)."""

    __slots__ = ("rate", "burst", "tokens", "stamp")

    def __init__(self, rate: float, burst: int):
        self.rate, self.burst, self.tokens, self.stamp = rate, float(burst), float(burst), time.monotonic()

    def full(self) -> bool:
        """As if unused: nothing is lost by forgetting it."""
        return self.tokens + (time.monotonic() - self.stamp) * self.rate >= self.burst

    def take(self) -> bool:
        now = time.monotonic()
        self.tokens = min(self.burst, self.tokens + (now - self.stamp) * self.rate)
        self.stamp = now
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True


class Sender:
    """What a door holds for one sender of a link (a Zenoh client, a ROS 2 node): its frames waiting
    for the link to be READY, its rate, and what it lost since the loop last counted it."""

    __slots__ = ("key", "name", "queue", "sends", "drops", "over")

    def __init__(self, key: Any, name: str):
        self.key = key  # (its place in the door's ``senders``)
        self.name = name
        self.queue: deque[Any] = deque()
        self.sends = Bucket(CLIENT_RATE_HZ, CLIENT_BURST)
        self.drops: dict[str, int] = {}
        self.over = False  # a frame of it was refused (rate, queue full) since its queue was last empty

    @staticmethod
    def size(item: Any) -> int:
        """The bytes of a queued item that count against :data:`DOOR_BYTES`."""
        return len(item)

    def idle(self) -> bool:
        """Nothing queued and nothing sent lately: forgetting it loses nothing."""
        return not self.queue and self.sends.full()


class Client(Sender):
    """What the door holds for one client of a link: a sender that also asks commands."""

    __slots__ = ("queries", "pending")

    def __init__(self, key: Any, name: str):
        super().__init__(key, name)
        self.queries = Bucket(QUERY_RATE_HZ, QUERY_BURST)
        self.pending = 0

    def idle(self) -> bool:
        return super().idle() and not self.pending and self.queries.full()


class SenderQueues(ABC):
    """The loop's side of a door whose senders each have a queue (this door, and the ROS 2 door's
    nodes): the senders with frames take turns, one frame each, while the link is READY, so one
    sender's flood fills only its own queue and costs each other sender one frame per turn.

    The turns are a queue of their own (``turns``: the senders with frames, in the order of their next
    turn), kept from one READY to the next: a sender whose frame went waits behind every other sender
    with frames.  (Going round the senders from the first one each time the link was READY again gave
    the first sender with a frame every turn: a link that sends one frame per READY never got past a
    flooder, and an honest sender's frames crossed only once the flood was over.)

    Places are bounded (:data:`MAX_CLIENTS`).  When every place is taken and a newcomer sends, a sender
    that is over its share (a frame of it refused, ``rate`` or ``client_queue``, since its queue was last
    empty) gives its place up, the one with the longest queue first (what it queued is dropped, counted
    ``evicted``): a sender that keeps to its share keeps its place however long its queue, and a flood
    of senders (names, DDS participants) cannot lock an honest one out.  Only when every place is held
    by a sender within its share is a newcomer refused (``clients``).  (The longest queue alone, as a
    shared buffer drops from it, evicted the honest sender with a backlog while the flood's senders,
    evicted in turn, came back with empty queues.)  A sender with nothing queued and nothing sent lately
    is forgotten.

    The endpoint fills the queues on its transport's threads, under ``lock`` (:meth:`_place`,
    :meth:`_admit`, :meth:`_queue`), and posts :meth:`_pump` to the loop once (``posted``)."""

    source: str  # the ``src`` of what is counted lost ("zenoh", "ros2"; a sender's: "zenoh:<name>")

    def __init__(self, door: Any, port: LinkPort):
        self.door = door  # its ``queued``: the bytes every link's door holds, under ``lock``
        self.port = port
        self.ready: bool | None = None
        self.senders: dict[Any, Sender] = {}
        self.turns: deque[Sender] = deque()  # the senders with frames queued, in the order of their next turn
        self.refused: dict[str, int] = {}  # frames and queries of no sender the door could keep
        self.gone: list[tuple[str, dict[str, int]]] = []  # what senders that gave up their places lost
        self.lock: threading.Lock = door.lock  # (one for the door: its byte count is shared)
        self.posted = False

    def _place(self, key: Any, make: Any) -> Sender | None:
        """Under the lock: the sender ``key`` names, given a place (``make()``) if new; None, counted
        ``clients``, when every place is held by a sender within its share."""
        sender = self.senders.get(key)
        if sender is not None:
            return sender
        if len(self.senders) >= MAX_CLIENTS:
            over = [s for s in self.senders.values() if s.over]
            if not over:
                self.refused["clients"] = self.refused.get("clients", 0) + 1
                return None
            self._evict(max(over, key=lambda s: len(s.queue)))
        sender = self.senders[key] = make()
        return sender

    def _evict(self, sender: Sender) -> None:
        """Under the lock: ``sender`` gives its place up; its frames are dropped (counted ``evicted``)."""
        del self.senders[sender.key]
        if sender.queue:
            self.turns.remove(sender)
            self.door.queued -= sum(sender.size(item) for item in sender.queue)
            sender.drops["evicted"] = sender.drops.get("evicted", 0) + len(sender.queue)
            sender.queue.clear()
        if sender.drops:
            self.gone.append((sender.name, sender.drops))

    def _admit(self, sender: Sender, size: int, max_size: int, door_bytes: int) -> bool:
        """Under the lock, on the transport's thread: whether ``sender`` may queue a frame of ``size``
        bytes (then they are counted in the door's), else the drop counted with its cause."""
        door = self.door
        if size > max_size:
            cause = "bad_frame"
        elif not sender.sends.take():
            cause = "rate"
        elif len(sender.queue) >= CLIENT_QUEUE or door.queued + size > door_bytes:
            cause = "client_queue"
        else:
            door.queued += size
            return True
        sender.drops[cause] = sender.drops.get(cause, 0) + 1
        if cause != "bad_frame":
            sender.over = True
        return False

    def _queue(self, sender: Sender, item: Any) -> None:
        """Under the lock: ``item`` (admitted) joins ``sender``'s queue; a sender that had nothing queued
        takes its place at the back of the turns."""
        if not sender.queue:
            self.turns.append(sender)
        sender.queue.append(item)

    def _pump(self) -> None:
        """On the loop: report what was dropped, then the senders' frames in turn while the link is READY."""
        door, port, turns = self.door, self.port, self.turns
        with self.lock:
            self.posted = False
            drops = [(sender.name, sender.drops) for sender in self.senders.values() if sender.drops]
            for sender in self.senders.values():
                sender.drops = {}
            drops += self.gone
            self.gone = []
            refused, self.refused = self.refused, {}
        for name, counts in drops:
            for cause, n in counts.items():
                port.lost(cause, 0, src=f"{self.source}:{name}", n=n)
        for cause, n in refused.items():
            port.lost(cause, 0, src=self.source, n=n)
        while port.ready:
            with self.lock:
                if not turns:
                    break
                sender = turns.popleft()
                item = sender.queue.popleft()
                door.queued -= sender.size(item)
                if sender.queue:
                    turns.append(sender)  # its next frame after everyone else's
                else:
                    sender.over = False
            self._forward(item, sender)
        with self.lock:  # senders with nothing queued, sending and asking nothing lately, are forgotten
            for key in [key for key, sender in self.senders.items() if sender.idle()]:
                del self.senders[key]

    @abstractmethod
    def _forward(self, item: Any, sender: Sender) -> None:
        """On the loop: hand ``sender``'s queued ``item`` to the link (a refused one is counted)."""

    def _drop_queued(self) -> None:
        """On close: what the senders still queue is given back to the doors' byte count."""
        with self.lock:
            for sender in self.senders.values():
                self.door.queued -= sum(sender.size(item) for item in sender.queue)
                sender.queue.clear()
            self.turns.clear()


class ZenohEndpoint(SenderQueues):
    kind = "zenoh"
    source = "zenoh"
    busy = False
    assumes_busy = False  # (hilgate.core.endpoint.Endpoint.assumes_busy: told BUSY by the link after a frame)
    phy = None  # (no PHY reports: hilgate.core.endpoint.Endpoint.phy)

    senders: dict[str, Client]  # (Clients: they ask commands too)

    def __init__(self, door: "ZenohDoor", port: LinkPort):
        super().__init__(door, port)
        self.info: dict[str, Any] = {}
        self.info_bucket = Bucket(QUERY_RATE_HZ * 4, QUERY_BURST * 4)
        session = door.session
        self.base = base = link_key(door.prefix, door.host, port.id, "")
        self.recv_pub = WatchedPublisher(session.declare_publisher(base + "recv"))
        self.state_pub = session.declare_publisher(base + "state")
        self.refresh()
        self.subscriber = session.declare_subscriber(base + "send/*", self._on_send)
        self.info_queryable = session.declare_queryable(base + "info", self._on_info)
        self.command_queryable = session.declare_queryable(base + "command/*", self._on_command)
        port.attach(self)

    def refresh(self) -> None:
        """The WELCOME an application asks for (kept ready: answered from Zenoh's thread)."""
        port = self.port
        self.info = {"link": port.id, "address": port.address, "packet": port.packet.name,
                     "max_payload": port.packet.max_payload, "version": wire.VERSION, "host": self.door.host}

    # -- link → applications (on the loop) --------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        if not self.recv_pub.matching:
            return ABSENT  # no application subscribes: nothing to encode or send
        self.recv_pub.put(_RECV.pack(frame.src & 0xFF, frame.dst & 0xFF, t) + bytes(frame.payload))
        return TAKEN

    def state(self, ready: bool) -> None:
        if ready != self.ready:
            self.ready = ready
            self.state_pub.put(b"\x01" if ready else b"\x00")
        if ready:
            self._pump()

    # -- applications → link (on Zenoh's threads: counted and queued, never waiting) ------------------

    def _client(self, key: str, leaf: str) -> Client | None:
        """The client a key names (under the lock); None, counted, when it cannot be kept."""
        name = key[len(self.base) + len(leaf) + 1:]
        if name not in self.senders and not CLIENT_NAME.fullmatch(name):
            self.refused["bad_client"] = self.refused.get("bad_client", 0) + 1
            return None
        return self._place(name, lambda: Client(name, name))  # type: ignore[return-value]

    def _on_send(self, sample: Any) -> None:
        with self.lock:
            client = self._client(str(sample.key_expr), "send")
            if client is not None and self._admit(client, len(sample.payload), MAX_SEND, DOOR_BYTES):
                self._queue(client, sample.payload.to_bytes())
            wake, self.posted = not self.posted, True
        if wake:
            self.door.post(self._pump)

    def _forward(self, data: bytes, sender: Sender) -> None:
        client = sender.name
        if not data:
            self._error(client, "a SEND needs at least the destination byte")
            self.port.lost("bad_frame", 0, src="app")
            return
        try:
            self.port.send_payload(data[1:], data[0])
        except PacketError as exc:
            self.port.lost("bad_frame", len(data) - 1, src="app")
            self._error(client, str(exc))

    def _error(self, client: str, message: str) -> None:
        self.door.session.put(self.base + f"error/{client}", json.dumps({"error": message}).encode())

    def _on_info(self, query: Any) -> None:
        with self.lock:
            allowed = self.info_bucket.take()
        if allowed:
            query.reply(self.base + "info", json.dumps(dict(self.info, ready=bool(self.ready))).encode())
        else:
            with self.lock:
                self.refused["query_refused"] = self.refused.get("query_refused", 0) + 1

    def _on_command(self, query: Any) -> None:
        key = str(query.key_expr)
        size = len(query.payload) if query.payload is not None else 0
        with self.lock:
            client = self._client(key, "command")
            if client is not None and (client.pending >= QUERY_PENDING or size > MAX_REQUEST
                                       or not client.queries.take()):
                client.drops["query_refused"] = client.drops.get("query_refused", 0) + 1
                client = None
            if client is not None:
                client.pending += 1
            wake, self.posted = not self.posted, True
        if wake:
            self.door.post(self._pump)
        if client is None:
            query.drop()  # unanswered: the client's get ends at its timeout
            return
        self.door.post(self._command, query, client, key)

    def _command(self, query: Any, client: Client, key: str) -> None:
        """On the loop: answer a command query (the reply goes out from here; Zenoh never waits)."""
        try:
            try:
                request = safejson.loads(query.payload.to_bytes(), max_bytes=MAX_REQUEST) if query.payload is not None else None
            except ValueError as exc:  # (bounded: a deep or huge request is refused before parsing)
                answer: Any = {"class": "ERROR", "error": f"a request is JSON: {exc}"}
            else:
                answer = self.port.command(request)
            query.reply(key, json.dumps(answer, default=str).encode())
        except Exception as exc:  # the client went away, the session is closing
            log.debug("command reply on %s: %s", key, exc)
        finally:
            query.drop()
            with self.lock:
                client.pending -= 1

    def close(self) -> None:
        self.port.detach(self)
        for entity in (self.subscriber, self.info_queryable, self.command_queryable, self.recv_pub, self.state_pub):
            try:
                entity.undeclare()
            except Exception:  # the session is closing already
                pass
        self._drop_queued()


class ZenohDoor:
    """Opens a link's Zenoh endpoint (the daemon gives it the session of :mod:`hilgate.daemon.network`)."""

    def __init__(self, session: Any, prefix: str, host: str, post: Any):
        self.session = session
        self.prefix = prefix
        self.host = host
        self.post = post
        self.queued = 0  # bytes of SENDs the endpoints hold
        self.lock = threading.Lock()

    def open(self, port: LinkPort) -> ZenohEndpoint:
        return ZenohEndpoint(self, port)

    def update(self, handle: ZenohEndpoint, port: LinkPort) -> ZenohEndpoint:
        handle.refresh()
        return handle

    def close(self, handle: ZenohEndpoint | None) -> None:
        if handle is not None:
            handle.close()
