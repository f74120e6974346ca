"""The GLI over stream sockets: a Unix socket per link and an optional TCP listener for all links.

The framing is :mod:`hilgate.gli.wire`, the conversation :mod:`hilgate.gli.session`.  A client on
a link's own Unix socket is attached to that link at once; a TCP client names its link in HELLO.
Each client is an endpoint of its link (:class:`~hilgate.core.endpoint.Endpoint`) and reaches the
link only through its :class:`~hilgate.core.endpoint.LinkPort`.  A client that breaks the framing
gets an ERROR and is disconnected; one that vanishes mid-frame just leaves; one that stops reading
is disconnected once ``output_cap`` bytes wait for it; none of them affects anything else.
"""

from __future__ import annotations

import logging
import os
import socket
from typing import Any, Callable

from . import wire
from .session import Command, Hello, Send, Session, WireError
from ..core.endpoint import ABSENT, TAKEN, LinkPort
from ..core.packets import PacketError
from ..core.streams import Connection, Listener, listen_unix, refuse

log = logging.getLogger(__name__)


class ClientLimits:
    """How many socket clients the daemon serves at once, in all and per link, and how much output it
    keeps for one that does not read."""

    def __init__(self, total: int = 256, per_link: int = 32, output_cap: int = 256 * 1024):
        self.total = total
        self.per_link = per_link
        self.output_cap = output_cap
        self.clients: set[GliClient] = set()


class GliClient:
    """One socket client: an endpoint of the link it is bound to."""

    kind = "socket"
    busy = False

    def __init__(self, sock: socket.socket, scheduler: Any, limits: ClientLimits,
                 lookup: Callable[[str], LinkPort | None], port: LinkPort | None = None):
        self.limits = limits
        self.lookup = lookup
        self.session = Session(port.id if port is not None else None)
        self.port: LinkPort | None = None
        self.last_state: bool | None = None
        self.connection = Connection(sock, scheduler, self._on_data, self._on_close, max_buffer=limits.output_cap)
        limits.clients.add(self)
        if port is not None:
            self._bind(port.id)

    def _bind(self, link_id: str) -> None:
        """Attach to a link: from now on its frames and READY/BUSY come here."""
        port = self.lookup(link_id)
        if port is None:
            self.fail(f"no link {link_id[:100]!r}")
            return
        if "socket" not in port.gli:
            self.fail(f"link {link_id!r} has no socket GLI (its gli: is [{', '.join(port.gli)}])")
            return
        if not port.attach(self):
            self.fail(f"too many clients on link {link_id!r} ({self.limits.per_link})")
            return
        self.port = port
        self.session.bound = True
        self.state(port.ready)

    def fail(self, message: str) -> None:
        self.connection.write(wire.encode_json(wire.ERROR, {"error": message}))
        self.connection.close()

    def _on_data(self, data: bytes) -> None:
        try:
            for event in self.session.receive(data):
                if self.connection.closed:
                    return
                self._handle(event)
        except WireError as exc:
            self.fail(str(exc))

    def _handle(self, event: Hello | Send | Command) -> None:
        match event:
            case Hello(link=link_id, first=first):
                if self.port is None:
                    self._bind(link_id)
                if self.port is not None and first:
                    self.connection.write(wire.encode_json(wire.WELCOME, welcome(self.port)))
            case Send(dst=dst, payload=payload):
                try:
                    self.port.send_payload(payload, dst)
                except PacketError as exc:  # refused: counted and traced like a bad frame from a queue
                    self.port.lost(exc.reason, len(payload), src="app")
                    self.connection.write(wire.encode_json(wire.ERROR, {"error": str(exc)}))
            case Command(request=request):
                self.connection.write(wire.encode_json(wire.REPLY, self.port.command(request)))

    # -- the endpoint ---------------------------------------------------------------------------

    def deliver(self, frame: Any, t: float) -> str:
        """``client_slow`` if the frame could not be queued for this client: it has stopped reading and
        its output passed the cap, so it is disconnected (it would only cost the daemon memory)."""
        if self.connection.closed:
            return ABSENT
        if self.connection.write(wire.encode_recv(frame.src, frame.dst, t, frame.payload)):
            return TAKEN
        self._too_slow()
        return "client_slow"

    def state(self, ready: bool) -> None:
        if ready != self.last_state:
            self.last_state = ready
            if not self.connection.write(wire.encode_state(ready)):
                self._too_slow()

    def _too_slow(self) -> None:
        if not self.connection.closed:
            if self.connection.write_failed:  # it closed its end (hilgate send does, once done): not slow
                log.debug("GLI client on %s has gone", self.port.id if self.port else "?")
            else:
                log.info("GLI client on %s stopped reading: disconnected", self.port.id if self.port else "?")
            self.connection.close()

    def _on_close(self) -> None:
        if self.session.pending:
            log.info("GLI client on %s left mid-frame (%d bytes)", self.port.id if self.port else "?",
                     self.session.pending)
        if self.port is not None:
            self.port.detach(self)
        self.limits.clients.discard(self)

    def close(self) -> None:
        self.connection.close()


def welcome(port: LinkPort) -> dict[str, Any]:
    return {"link": port.id, "address": port.address, "packet": port.packet.name,
            "max_payload": port.packet.max_payload, "version": wire.VERSION}


def accept(sock: socket.socket, scheduler: Any, limits: ClientLimits, lookup: Callable[[str], LinkPort | None],
           port: LinkPort | None = None) -> None:
    """A new socket client, unless the daemon serves as many as it may: then it is told why and closed."""
    if len(limits.clients) >= limits.total:
        log.info("GLI client refused: %d clients already (--max-clients)", len(limits.clients))
        refuse(sock, wire.encode_json(wire.ERROR, {"error": f"too many clients ({limits.total})"}))
        return
    GliClient(sock, scheduler, limits, lookup, port)


class SocketDoor:
    """Opens each link's Unix socket ``DIRECTORY/ID.sock`` (0660, the daemon's group)."""

    def __init__(self, directory: str, scheduler: Any, limits: ClientLimits,
                 lookup: Callable[[str], LinkPort | None], group: int | None = None):
        self.directory = directory
        self.scheduler = scheduler
        self.limits = limits
        self.lookup = lookup
        self.group = group
        os.makedirs(directory, mode=0o750, exist_ok=True)

    def open(self, port: LinkPort) -> Listener | None:
        """The link's socket, unless its ``gli:`` leaves it out."""
        if "socket" not in port.gli:
            return None
        path = os.path.join(self.directory, f"{port.id}.sock")
        return Listener(listen_unix(path, group=self.group), self.scheduler,
                        lambda sock: accept(sock, self.scheduler, self.limits, self.lookup, port), path)

    def update(self, handle: Listener | None, port: LinkPort) -> Listener | None:
        if handle is None:
            return self.open(port)
        if "socket" not in port.gli:  # a reload took the socket away (clients already on it stay)
            handle.close()
            return None
        return handle

    def close(self, handle: Listener | None) -> None:
        if handle is not None:
            handle.close()


def tcp_listener(host: str, port: int, scheduler: Any, limits: ClientLimits,
                 lookup: Callable[[str], LinkPort | None]) -> Listener:
    """One TCP listener for every link: a client names its link in HELLO."""
    sock = socket.create_server((host, port), reuse_port=False)
    sock.setblocking(False)
    return Listener(sock, scheduler, lambda conn: accept(conn, scheduler, limits, lookup))
