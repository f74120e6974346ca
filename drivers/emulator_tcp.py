"""A loopback TCP port for an emulated modem (``emulate: {tcp: 9200}``), each client a host of its own: what
every emulated modem on TCP shares, whatever protocol it speaks."""

from __future__ import annotations

import itertools
import logging
import socket
from typing import Any

from hilgate.core.streams import Connection, Listener

log = logging.getLogger(__name__)

MAX_TCP_CLIENTS = 8  # an emulated modem's TCP port: hosts at once (a real S2C serves a few on its port)
TCP_OUTPUT_CAP = 256 * 1024  # answers kept for a TCP host that does not read (beyond: not sent)


class TcpHosts:
    """A loopback listener; each client is a host with its own protocol state.

    At most :data:`MAX_TCP_CLIENTS` at once (each holds a codec and up to :data:`TCP_OUTPUT_CAP` bytes of
    answers it has not read).  When a host connects to a full port, the host that has been quiet longest
    (connected or last heard from earliest) is closed to make room, and counted in :attr:`evicted`:
    refusing the newcomer instead let eight connections that never said anything keep the lab's own
    software out for as long as they stayed (issue 37).  A host that talks keeps its place; a stranger
    can still close one that only listens, by connecting eight times, as it could unplug a real modem's
    Ethernet cable: the port is as open as a real modem's (docs/security.md says how to restrict it)."""

    def __init__(self, port: int, scheduler: Any, on_data, on_connect, name: str, host: str = "127.0.0.1",
                 on_disconnect=None):
        self.scheduler = scheduler
        self.on_data = on_data
        self.on_connect = on_connect
        self.on_disconnect = on_disconnect
        self.name = name
        self.clients: set[TcpClient] = set()
        self.evicted = 0
        self.heard = itertools.count()  # an order of who was heard from last (no clock needed)
        sock = socket.create_server((host, port))
        sock.setblocking(False)
        self.listener = Listener(sock, scheduler, self._accept)
        log.info("%s: emulated modem on tcp://%s:%d", name, host, port)

    def _accept(self, sock: socket.socket) -> None:
        if len(self.clients) >= MAX_TCP_CLIENTS:
            # hosts that left but whose end of file the loop has not read yet hold no place: a host that
            # reconnects at once does not push out another for its own old connection (seen on a loaded host)
            for client in [c for c in self.clients if c.connection.hung_up()]:
                client.connection.close()
        if len(self.clients) >= MAX_TCP_CLIENTS:
            quiet = min(self.clients, key=lambda c: c.last_heard)
            self.evicted += 1
            if self.evicted & (self.evicted - 1) == 0:  # the 1st, 2nd, 4th, 8th…: a flood costs a few lines
                log.warning("%s: emulated modem closed the TCP host quiet longest to serve a new one: %d "
                            "connected already (%d closed so far)", self.name, len(self.clients), self.evicted)
            quiet.close()
        client = TcpClient(self, sock)
        self.clients.add(client)
        self.on_connect(client)

    def close(self) -> None:
        for client in list(self.clients):
            client.connection.close()
        self.listener.close()


class TcpClient:
    def __init__(self, hosts: TcpHosts, sock: socket.socket):
        self.hosts = hosts
        self.last_heard = next(hosts.heard)
        self.connection = Connection(sock, hosts.scheduler, self._data, self._closed, max_buffer=TCP_OUTPUT_CAP)

    def _data(self, data: bytes) -> None:
        self.last_heard = next(self.hosts.heard)
        self.hosts.on_data(self, data)

    def _closed(self) -> None:
        self.hosts.clients.discard(self)
        if self.hosts.on_disconnect is not None:
            self.hosts.on_disconnect(self)  # its protocol state goes with it (1 500 clients leave nothing)

    def write(self, data: bytes) -> None:
        self.connection.write(data)

    def close(self) -> None:
        self.connection.close()
