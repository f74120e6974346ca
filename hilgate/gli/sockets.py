"""The GLI over stream sockets: a Unix socket per link and an optional TCP listener for all links.

The framing is :mod:`hilgate.gli.wire`, the conversation :mod:`hilgate.gli.session`.  A client on
a link's own Unix socket is attached to that link at once (the socket's mode and group say who may
connect); a TCP client is sent a CHALLENGE and names its link in a HELLO that proves it holds the
daemon's token (:mod:`hilgate.gli.token`), or is told why not and closed.  Connections that have not
proved it yet wait in a :class:`~hilgate.core.waiting_room.WaitingRoom` (bounded in all and per
address; a newcomer is always let in, and the oldest of the address holding the most makes room) and
are closed ``auth_timeout_s`` after they connected, however slowly their HELLO trickles in: a peer
without the token cannot take the places of those that have it.
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
from .token import TokenCheck
from ..core.endpoint import ABSENT, TAKEN, LinkPort
from ..core.packets import PacketError
from ..core.streams import Connection, Listener, listen_unix, refuse
from ..core.waiting_room import WaitingRoom

log = logging.getLogger(__name__)


class ClientLimits:
    """How many socket clients the daemon serves at once, in all and per link, and how much output it
    keeps for one that does not read; how many TCP connections may wait to authenticate, in all and
    from one address, and for how long (a handshake is one round trip: 5 s is plenty on any lab
    network); and what was refused on TCP (``auth_pending``: closed to make room for a newcomer)."""

    def __init__(self, total: int = 256, per_link: int = 32, output_cap: int = 256 * 1024,
                 pending_total: int = 64, pending_per_address: int = 8, auth_timeout_s: float = 5.0):
        self.total = total
        self.per_link = per_link
        self.output_cap = output_cap
        self.auth_timeout_s = auth_timeout_s
        self.clients: set[GliClient] = set()
        self.pending = WaitingRoom(pending_total, pending_per_address)  # TCP connections not authenticated yet
        self.refused = {"auth": 0, "auth_timeout": 0, "auth_pending": 0}

    def refuse(self, cause: str, address: str, detail: str) -> None:
        """Count a refused TCP connection and log it, the 1st, 2nd, 4th, 8th… of each cause only (a
        flood of them costs a few log lines)."""
        self.refused[cause] += 1
        count = self.refused[cause]
        if count & (count - 1) == 0:
            log.warning("TCP GLI: refused %s: %s (%d refused so far for this cause)", address, detail, count)


class GliClient:
    """One socket client: an endpoint of the link it is bound to."""

    kind = "socket"
    busy = False
    assumes_busy = False  # (hilgate.core.endpoint.Endpoint.assumes_busy: told BUSY by the link after a frame)
    phy = None  # (no PHY reports: hilgate.core.endpoint.Endpoint.phy)

    def __init__(self, sock: socket.socket, scheduler: Any, limits: ClientLimits,
                 lookup: Callable[[str], LinkPort | None], port: LinkPort | None = None,
                 check: TokenCheck | None = None, address: str = ""):
        self.limits = limits
        self.lookup = lookup
        self.scheduler = scheduler
        self.session = Session(port.id if port is not None else None, check)
        self.port: LinkPort | None = None
        self.last_state: bool | None = None
        self.address = address
        self.waiting = check is not None  # among the TCP connections that have not authenticated yet
        self.auth_timer = None
        self.connection = Connection(sock, scheduler, self._on_data, self._on_close, max_buffer=limits.output_cap)
        limits.clients.add(self)
        if check is not None:  # one deadline for the whole handshake, from now: not renewed by its bytes
            self.auth_timer = scheduler.after_wall(limits.auth_timeout_s, self._auth_timeout)
            self.connection.write(self.session.challenge())
            for older in limits.pending.admit(self, address):
                older._make_room()
        if port is not None:
            self._bind(port.id)

    def _stop_waiting(self) -> None:
        """Authenticated, or gone: its place among the pending is free again (once)."""
        if not self.waiting:
            return
        self.waiting = False
        self.scheduler.cancel(self.auth_timer)
        self.auth_timer = None
        self.limits.pending.leave(self)

    def _make_room(self) -> None:
        """The room is full and this one has waited longest of the address holding the most: it goes."""
        detail = f"too many connections wait to authenticate from {self.address}: the oldest is closed"
        self.limits.refuse("auth_pending", self.address, detail)
        self.fail(detail)

    def _auth_timeout(self) -> None:
        self.auth_timer = None
        limit = f"no HELLO within {self.limits.auth_timeout_s:g} s"
        self.limits.refuse("auth_timeout", self.address, limit)
        self.fail(limit)

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
            if not self.session.authenticated:  # a TCP peer that has not proved the token: counted
                self.limits.refuse("auth", self.address, str(exc))
            self.fail(str(exc))

    def _handle(self, event: Hello | Send | Command) -> None:
        match event:
            case Hello(link=link_id, first=first):
                self._stop_waiting()
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
        its output passed the cap, so it is disconnected (it would only cost the daemon memory).  A
        client that has closed its end is ABSENT: the frame is not its loss."""
        if self.connection.closed or self.connection.write_failed:
            return ABSENT
        if self.connection.write(wire.encode_recv(frame.src, frame.dst, t, frame.payload)):
            return TAKEN
        if self.connection.write_failed:  # it has just gone (closed its end): not slow, and not here
            return ABSENT
        self._too_slow()
        return "client_slow"

    def state(self, ready: bool) -> None:
        if ready != self.last_state:
            self.last_state = ready
            if not self.connection.write(wire.encode_state(ready)):
                self._too_slow()

    def _too_slow(self) -> None:
        if self.connection.closed:
            return
        if self.connection.write_failed:
            # it closed its end (hilgate send does, once done): not slow, and what it sent before is still
            # in the socket; the connection closes when reading ends, once that is handled (core.streams)
            log.debug("GLI client on %s has gone", self.port.id if self.port else "?")
            return
        log.info("GLI client on %s stopped reading: disconnected", self.port.id if self.port else "?")
        self.connection.close()

    def _on_close(self) -> None:
        self._stop_waiting()
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
           port: LinkPort | None = None, check: TokenCheck | None = None) -> None:
    """A new socket client, unless the daemon serves as many as it may: then it is told why and closed.
    On TCP it is let in even when as many wait to authenticate as may (in all, or from its address): the
    oldest of those from the address holding the most makes room (:mod:`hilgate.core.waiting_room`)."""
    if len(limits.clients) - len(limits.pending) >= limits.total:  # strangers waiting to authenticate take no place
        log.info("GLI client refused: %d clients already (--max-clients)", len(limits.clients) - len(limits.pending))
        refuse(sock, wire.encode_json(wire.ERROR, {"error": f"too many clients ({limits.total})"}))
        return
    address = ""
    if check is not None:
        try:
            address = str(sock.getpeername()[0])
        except OSError:  # already gone
            sock.close()
            return
    GliClient(sock, scheduler, limits, lookup, port, check, address)


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
                 lookup: Callable[[str], LinkPort | None], check: TokenCheck) -> Listener:
    """One TCP listener for every link: a client proves the token and names its link in HELLO."""
    sock = socket.create_server((host, port), reuse_port=False)
    sock.setblocking(False)
    return Listener(sock, scheduler, lambda conn: accept(conn, scheduler, limits, lookup, None, check))
