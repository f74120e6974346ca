"""The GLI over Zenoh: an application anywhere on the network reaches a link by id.

The serving daemon declares, for each of its links, under ``<prefix>/link/<id>/``:

=================  ==============  ===================================================================
key                who puts        payload
=================  ==============  ===================================================================
``send``           application     ``u8 dst`` (255 broadcast) then the payload; optional attachment:
                                   the application's client id (UTF-8), for its errors
``recv``           daemon          ``u8 src | u8 dst | f64 model time (big-endian)`` then the payload
``state``          daemon          ``u8``: 1 READY, 0 BUSY (when it changes)
``error/<client>`` daemon          UTF-8 JSON ``{"error": "..."}`` for a frame that client sent
``info``           queryable       UTF-8 JSON ``{"link", "address", "packet", "max_payload", "version",
                                   "ready", "host"}`` (the socket GLI's WELCOME, plus READY and host)
``command``        queryable       query payload: a JSON request as the socket GLI's COMMAND; reply:
                                   its answer
=================  ==============  ===================================================================

These are the bodies of the socket GLI's SEND, RECV and STATE messages (:mod:`hilgate.gli.wire`),
so an application in C, C++ or Rust needs a Zenoh session and ``struct`` packing, nothing of hilgate.
Zenoh calls back on its own threads; everything that touches the link is posted to the loop.
"""

from __future__ import annotations

import json
import logging
import struct
import threading
from typing import Any

from ..core import safejson
from ..core.backend import AppFrame
from ..core.endpoint import ABSENT, TAKEN, LinkPort
from ..core.packets import PacketError
from . import wire

log = logging.getLogger(__name__)

__all__ = ["WatchedPublisher", "ZenohDoor", "ZenohEndpoint", "link_key"]

_RECV = struct.Struct(">BBd")
COMMAND_WAIT_S = 2.0


def link_key(prefix: str, link_id: str, leaf: str) -> str:
    return f"{prefix}/link/{link_id}/{leaf}"


class WatchedPublisher:
    """A Zenoh publisher and whether anybody subscribes to it (``matching``), kept up to date by Zenoh
    (a matching listener) rather than asked before every message: asking costs about 2 µs, a frame's
    whole pass through the daemon about 40."""

    __slots__ = ("publisher", "matching", "_listener")

    def __init__(self, publisher: Any):
        self.publisher = publisher
        self.matching = False
        self._listener = publisher.declare_matching_listener(self._changed)
        self.matching = publisher.matching_status  # read after the listener exists: no change is missed

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


class ZenohEndpoint:
    kind = "zenoh"
    busy = False

    def __init__(self, door: "ZenohDoor", port: LinkPort):
        self.door = door
        self.port = port
        self.info: dict[str, Any] = {}
        self.ready: bool | None = None
        session, prefix = door.session, door.prefix
        self.recv_pub = WatchedPublisher(session.declare_publisher(link_key(prefix, port.id, "recv")))
        self.state_pub = session.declare_publisher(link_key(prefix, port.id, "state"))
        self.refresh()
        self.subscriber = session.declare_subscriber(link_key(prefix, port.id, "send"), self._on_send)
        self.info_queryable = session.declare_queryable(link_key(prefix, port.id, "info"), self._on_info)
        self.command_queryable = session.declare_queryable(link_key(prefix, port.id, "command"), self._on_command)
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

    # -- applications → link (Zenoh's threads, posted to the loop) ------------------------------------

    def _on_send(self, sample: Any) -> None:
        data = sample.payload.to_bytes()
        client = sample.attachment.to_bytes().decode("utf-8", "replace")[:64] if sample.attachment else ""
        self.door.post(self._send, data, client)

    def _send(self, data: bytes, client: str) -> None:
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
        if client and all(c.isalnum() or c in "_-." for c in client):
            self.door.session.put(link_key(self.door.prefix, self.port.id, f"error/{client}"),
                                  json.dumps({"error": message}).encode())

    def _on_info(self, query: Any) -> None:
        info = dict(self.info, ready=bool(self.ready))
        query.reply(query.key_expr, json.dumps(info).encode())

    def _on_command(self, query: Any) -> None:
        try:
            request = safejson.loads(query.payload.to_bytes()) if query.payload is not None else None
        except ValueError as exc:  # (bounded: a deep or huge request is refused before parsing)
            query.reply(query.key_expr, json.dumps({"class": "ERROR", "error": f"a request is JSON: {exc}"}).encode())
            return
        done = threading.Event()
        answer: list[Any] = []

        def ask() -> None:
            try:
                answer.append(self.port.command(request))
            finally:
                done.set()

        self.door.post(ask)
        if not done.wait(COMMAND_WAIT_S) or not answer:
            query.reply(query.key_expr, json.dumps({"class": "ERROR", "error": "the daemon did not answer"}).encode())
            return
        query.reply(query.key_expr, json.dumps(answer[0]).encode())

    def close(self) -> None:
        self.port.detach(self)
        for entity in (self.subscriber, self.info_queryable, self.command_queryable, self.recv_pub, self.state_pub):
            try:
                entity.undeclare()
            except Exception:  # the session is closing already
                pass


class ZenohDoor:
    """Opens a link's Zenoh endpoint (the daemon gives it the session of :mod:`hilgate.daemon.network`)."""

    def __init__(self, session: Any, prefix: str, host: str, post: Any):
        self.session = session
        self.prefix = prefix
        self.host = host
        self.post = post

    def open(self, port: LinkPort) -> ZenohEndpoint:
        return ZenohEndpoint(self, port)

    def update(self, handle: ZenohEndpoint, port: LinkPort) -> ZenohEndpoint:
        handle.refresh()
        return handle

    def close(self, handle: ZenohEndpoint | None) -> None:
        if handle is not None:
            handle.close()
