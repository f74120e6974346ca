"""The GLI over stream sockets: a Unix socket per link and an optional TCP listener for all links.

The framing is :mod:`hilgate.gli_wire`.  A client on a link's own Unix socket is attached to that
link at once; a TCP client names its link in HELLO.  A client that breaks the framing gets an ERROR
and is disconnected; one that vanishes mid-frame just leaves; neither affects anything else.
"""

from __future__ import annotations

import logging
import socket
from typing import TYPE_CHECKING, Any

from . import wire
from ..core.packets import PacketError
from ..core.streams import Connection, refuse

if TYPE_CHECKING:
    from ..daemon.router import Link, Router

log = logging.getLogger(__name__)


class GliClient:
    kind = "socket"

    def __init__(self, sock: socket.socket, scheduler: Any, router: "Router", link_id: str | None = None,
                 output_cap: int = 256 * 1024):
        self.router = router
        self.decoder = wire.Decoder()
        self.link: Link | None = None
        self.fixed_link = link_id
        self.last_state: bool | None = None
        self.dropped = 0
        self.welcomed = False
        self.connection = Connection(sock, scheduler, self._on_data, self._on_close, max_buffer=output_cap)
        if link_id is not None:
            self._bind(link_id)

    def _bind(self, link_id: str) -> None:
        """Attach to a link: from now on its frames and READY/BUSY come here."""
        link = self.router.links.get(link_id)
        if link is None:
            self.fail(f"no link {link_id[:100]!r}")
            return
        if not link.attach_client(self):
            self.fail(f"too many clients on link {link_id!r} ({self.router.max_link_clients})")
            return
        self.link = link
        self.state(link.ready)

    def fail(self, message: str) -> None:
        self.connection.write(wire.encode_json(wire.ERROR, {"error": message}))
        self.connection.close()

    def _on_data(self, data: bytes) -> None:
        try:
            messages = self.decoder.feed(data)
        except wire.WireError as exc:
            self.fail(str(exc))
            return
        for kind, body in messages:
            if self.connection.closed:
                return
            try:
                self._handle(kind, body)
            except wire.WireError as exc:
                self.fail(str(exc))

    def _handle(self, kind: int, body: bytes) -> None:
        if kind == wire.HELLO:
            hello = wire.decode_json(body)
            link_id = hello.get("link") if isinstance(hello, dict) else None
            if not isinstance(link_id, str):
                raise wire.WireError('HELLO needs {"link": "<id>"}')
            if self.link is None:
                self._bind(link_id)
            elif self.link.id != link_id:
                raise wire.WireError(f"this socket belongs to link {self.link.id!r}")
            if self.link is not None and not self.welcomed:
                self.welcomed = True
                self.connection.write(wire.encode_json(wire.WELCOME, self.link.welcome()))
        elif kind == wire.SEND:
            if self.link is None:
                raise wire.WireError("say HELLO first")
            dst, payload = wire.decode_send(body)
            try:
                self.link.from_client(payload, dst)
            except PacketError as exc:  # refused: counted and traced like a bad frame from a queue
                self.link.bad_frame(exc.reason, len(payload))
                self.connection.write(wire.encode_json(wire.ERROR, {"error": str(exc)}))
        elif kind == wire.COMMAND:
            if self.link is None:
                raise wire.WireError("say HELLO first")
            request = wire.decode_json(body)
            self.connection.write(wire.encode_json(wire.REPLY, self.router.command(self.link, request)))
        else:
            raise wire.WireError(f"unexpected message type {kind}")

    def deliver(self, src: int, dst: int, t: float, payload: bytes) -> bool:
        """False if the frame could not be queued for this client: it has stopped reading and its
        output passed the cap, so it is disconnected (it would only cost the daemon memory)."""
        if self.connection.write(wire.encode_recv(src, dst, t, payload)):
            return True
        self.dropped += 1
        self._too_slow()
        return False

    def state(self, ready: bool) -> None:
        if ready != self.last_state:
            self.last_state = ready
            if not self.connection.write(wire.encode_state(ready)):
                self._too_slow()

    def _too_slow(self) -> None:
        if not self.connection.closed:
            log.info("GLI client on %s stopped reading: disconnected", self.link.id if self.link else "?")
            self.connection.close()

    def _on_close(self) -> None:
        if self.decoder.pending:
            log.info("GLI client on %s left mid-frame (%d bytes)", self.link.id if self.link else "?",
                     self.decoder.pending)
        if self.link is not None:
            self.link.detach_client(self)
        self.router.clients.discard(self)

    def close(self) -> None:
        self.connection.close()


def refuse_client(sock: socket.socket, message: str) -> None:
    """Tell a client why it cannot stay (one ERROR) and close."""
    refuse(sock, wire.encode_json(wire.ERROR, {"error": message}))
