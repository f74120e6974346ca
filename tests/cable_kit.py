"""The cable between a driver and its emulated modem, which a test pulls and plugs back: the driver's port
is the cable's end (``where``), and bytes pass to and from the modem as a cable or a network would.

Both kinds answer ``unplug()``, ``plug(garbage)`` and ``close()``, so a test of a replug is written once
for every row of the driver table (:mod:`bench_kit` picks the kind from the row's way):

- :class:`PtyCable`, a serial line: a pty the test unplugs (its path vanishes, as a USB adapter's does)
  and plugs back, the emulated modem's pty on the other side; the modem never notices, as a modem on the
  far end of a pulled adapter does not; ``garbage`` is what the line carries as the adapter comes back;
- :class:`TcpCable`, a network: a loopback port the test closes (the host's connection dropped, a new one
  refused) and opens again, each connection relayed to a connection of its own to the emulated modem's
  port, as a host's new connection reaches a modem; ``garbage`` comes first on the first connection after
  the plug, before any byte of the modem's.
"""

from __future__ import annotations

import os
import select
import socket
import threading
import time
import tty

from daemon_kit import PluggablePty, free_port, in_background

BLOCK = 65536


class PtyCable(PluggablePty):
    """A serial line to the emulated modem's pty ``modem`` (the module's docstring); ``where`` is the path
    the driver opens."""

    def __init__(self, path: str, modem: str):
        self.modem = os.open(modem, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.modem)
        self.where = path
        super().__init__(path)
        self.from_modem, self.reader = in_background(self._relay)

    def plug(self, garbage: bytes = b"") -> None:
        super().plug()
        if garbage:
            self.write(garbage)

    def answer(self, data: bytes) -> bytes:
        try:
            os.write(self.modem, data)
        except OSError:  # the emulated modem's end is gone (its daemon stopping): the bytes fall off the line
            pass
        return b""

    def _relay(self, stop: threading.Event) -> None:
        while not stop.is_set():
            ready, _, _ = select.select([self.modem], [], [], 0.02)
            if ready:
                self.write(os.read(self.modem, 4096))  # (dropped while unplugged)

    def close(self) -> None:
        self.from_modem.set()
        self.reader.join()
        super().close()
        os.close(self.modem)


class TcpCable:
    """A network to the emulated modem's loopback port ``modem`` (the module's docstring); ``where`` is the
    loopback port the driver connects to, the same across replugs."""

    def __init__(self, modem: int):
        self.modem = modem
        self.where = free_port()
        self.lock = threading.Lock()  # held while sockets are used: unplug() closes none under the relay
        self.listener: socket.socket | None = None
        self.peers: dict[socket.socket, socket.socket] = {}  # each end of a relayed connection → the other
        self.garbage = b""
        self.plug()
        self.stop, self.thread = in_background(self._serve)

    def plug(self, garbage: bytes = b"") -> None:
        with self.lock:
            self.garbage = garbage
            self.listener = socket.create_server(("127.0.0.1", self.where))  # (SO_REUSEADDR: the same port)

    def unplug(self) -> None:
        with self.lock:
            if self.listener is not None:
                self.listener.close()
                self.listener = None
            for sock in list(self.peers):
                self._drop(sock)

    def _serve(self, stop: threading.Event) -> None:
        while not stop.is_set():
            with self.lock:
                sockets = [*([self.listener] if self.listener is not None else []), *self.peers]
                ready = select.select(sockets, [], [], 0.02)[0] if sockets else []
                for sock in ready:
                    if sock is self.listener:
                        self._accept()
                    elif sock in self.peers:
                        self._pass(sock)
            if not sockets:
                time.sleep(0.02)

    def _accept(self) -> None:
        host, _ = self.listener.accept()
        try:
            modem = socket.create_connection(("127.0.0.1", self.modem))
        except OSError:
            host.close()  # no modem behind the cable: the host's connection ends at once
            return
        if self.garbage:
            host.sendall(self.garbage)
            self.garbage = b""
        self.peers[host], self.peers[modem] = modem, host

    def _pass(self, sock: socket.socket) -> None:
        try:
            data = sock.recv(BLOCK)
            if data:
                self.peers[sock].sendall(data)
                return
        except OSError:
            pass
        self._drop(sock)

    def _drop(self, sock: socket.socket) -> None:
        other = self.peers.pop(sock, None)
        self.peers.pop(other, None)
        for end in (sock, other):
            if end is not None:
                end.close()

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.unplug()
