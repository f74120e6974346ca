"""Strangers at the doors, on loopback: the attacks of issue 37 (items 4 to 6) as a test makes them.

A stranger has no token and comes from addresses of its own: Linux routes all of 127/8 to the loopback
interface, so a test connects from ``127.0.0.2``…``127.0.0.9`` (:data:`STRANGERS`) to a daemon on
``127.0.0.1``, as eight hosts of a lab network would, while the honest client comes from
``127.0.0.1``.  :func:`idle` opens connections that never say anything; :class:`Slowloris` keeps
connections that trickle a message a byte at a time and never finish it, opening a new one for each the
server closes (the attack keeps its places).  :func:`accept_queue` tells when the server has taken every
connection the kernel completed for it (so a test knows the strangers are in before the honest client
comes, without sleeping).
"""

from __future__ import annotations

import selectors
import socket
import threading
import time

from daemon_kit import HANG_GUARD_S, wait_until

STRANGERS = tuple(f"127.0.0.{n}" for n in range(2, 10))


def connect(port: int, source: str = "127.0.0.1", host: str = "127.0.0.1") -> socket.socket:
    """A TCP connection to ``host:port`` from the loopback address ``source``."""
    return socket.create_connection((host, port), timeout=HANG_GUARD_S, source_address=(source, 0))


def accept_queue(port: int) -> int | None:
    """How many connections wait in the accept queue of the listener on loopback ``port`` (the Recv-Q
    of a listening socket in /proc/net/tcp), or None if nothing listens there."""
    with open("/proc/net/tcp") as table:
        next(table)
        for line in table:
            fields = line.split()
            local, state, queues = fields[1], fields[3], fields[4]
            if state == "0A" and int(local.split(":")[1], 16) == port:
                return int(queues.split(":")[1], 16)
    return None


def listening_addresses(port: int) -> list[str]:
    """The IPv4 addresses TCP listeners on ``port`` are bound to (/proc/net/tcp)."""
    found = []
    with open("/proc/net/tcp") as table:
        next(table)
        for line in table:
            fields = line.split()
            address, _, local_port = fields[1].partition(":")
            if fields[3] == "0A" and int(local_port, 16) == port:
                found.append(socket.inet_ntoa(int(address, 16).to_bytes(4, "little")))
    return found


def taken(port: int) -> None:
    """Wait (a hang guard only) until the listener on ``port`` has accepted every completed connection."""
    wait_until(lambda: accept_queue(port) == 0, f"the listener on port {port} to accept its connections")


def idle(port: int, sources=STRANGERS, per_address: int = 8) -> list[socket.socket]:
    """``per_address`` connections from each of ``sources`` that never send anything, all accepted."""
    sockets = [connect(port, source) for source in sources for _ in range(per_address)]
    taken(port)
    return sockets


def closed_by_peer(sock: socket.socket) -> bool:
    """Whether the server has closed ``sock`` (what it sent before is read and dropped); never blocks."""
    sock.setblocking(False)
    try:
        while True:
            data = sock.recv(65536)
            if not data:
                return True
    except BlockingIOError:
        return False
    except OSError:
        return True


class Slowloris:
    """``per_address`` connections from each of ``sources`` to loopback ``port``, each sending ``payload``
    one byte every ``interval_s`` and never its end; whatever the server sends is read and dropped.  A
    connection the server closes is opened again at once.  ``opened`` counts every connection made."""

    def __init__(self, port: int, payload: bytes, sources=STRANGERS, per_address: int = 8,
                 interval_s: float = 1.0):
        self.port = port
        self.payload = payload[:-1]  # its last byte never comes
        self.sources = [source for source in sources for _ in range(per_address)]
        self.interval_s = interval_s
        self.opened = 0
        self.selector = selectors.DefaultSelector()
        self.stop_event = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> "Slowloris":
        for source in self.sources:
            self._open(source)
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop_event.set()
        self.thread.join(HANG_GUARD_S)
        for key in list(self.selector.get_map().values()):
            key.fileobj.close()
        self.selector.close()

    def _open(self, source: str) -> None:
        while not self.stop_event.is_set():
            try:
                sock = connect(self.port, source)
                break
            except OSError:  # refused at the door: come again
                time.sleep(0.01)
        else:
            return
        sock.setblocking(False)
        self.opened += 1
        # [source, bytes sent, when the next byte is due]
        self.selector.register(sock, selectors.EVENT_READ, [source, 0, time.monotonic()])

    def _run(self) -> None:
        while not self.stop_event.is_set():
            now = time.monotonic()
            states = list(self.selector.get_map().values())
            for key in states:
                state = key.data
                if state[2] <= now and state[1] < len(self.payload):
                    try:
                        key.fileobj.send(self.payload[state[1]:state[1] + 1])
                        state[1] += 1
                    except OSError:
                        self._reopen(key)
                        continue
                    state[2] = now + self.interval_s
            due = min((key.data[2] for key in self.selector.get_map().values()), default=now + 0.1)
            for key, _ in self.selector.select(max(0.0, min(due - time.monotonic(), 0.1))):
                try:
                    data = key.fileobj.recv(65536)
                except BlockingIOError:
                    continue
                except OSError:
                    data = b""
                if not data:
                    self._reopen(key)

    def _reopen(self, key) -> None:
        self.selector.unregister(key.fileobj)
        key.fileobj.close()
        self._open(key.data[0])


def first_tries(attempt, count: int) -> list[bool]:
    """``attempt()`` ``count`` times: whether each got in at the first try (True) or was kept out."""
    results = []
    for _ in range(count):
        try:
            results.append(bool(attempt()))
        except Exception:  # kept out: refused, closed, timed out; the figure says how often
            results.append(False)
    return results
