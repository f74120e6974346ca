"""A non-blocking stream socket in the real-time loop: read callback in, bounded output buffer out.

A client that stops reading must not stall the loop or grow the daemon's memory: output beyond
``max_buffer`` bytes is refused (the caller counts it as dropped) until the client catches up.
A client may send its last frames and close at once; a failed write (EPIPE) therefore only stops
output, and the connection closes when reading ends, after everything it sent has been handled.
"""

from __future__ import annotations

import logging
import socket
from typing import Any, Callable

log = logging.getLogger(__name__)


class Outbox:
    """Output for a non-blocking descriptor: written at once when the kernel takes it, the rest kept
    (at most ``max_buffer`` bytes) and flushed when the loop says the descriptor can take more."""

    def __init__(self, scheduler: Any, fd: int, send: Callable[[bytes], int], on_error: Callable[[OSError], Any],
                 max_buffer: int):
        self.scheduler = scheduler
        self.fd = fd
        self.send = send
        self.on_error = on_error
        self.max_buffer = max_buffer
        self._pending = bytearray()

    def write(self, data: bytes) -> bool:
        """False (nothing queued) when the backlog is full or the descriptor failed."""
        if self._pending:
            if len(self._pending) + len(data) > self.max_buffer:
                return False
            self._pending += data
            return True
        try:
            sent = self.send(data)
        except (BlockingIOError, InterruptedError):
            sent = 0
        except OSError as exc:
            self.on_error(exc)
            return False
        if sent < len(data):
            self._pending += data[sent:]
            self.scheduler.set_writer(self.fd, self._writable)
        return True

    def _writable(self) -> None:
        try:
            sent = self.send(self._pending)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self.on_error(exc)
            return
        del self._pending[:sent]
        if not self._pending:
            self.scheduler.set_writer(self.fd, None)

    def clear(self) -> None:
        self._pending.clear()
        self.scheduler.set_writer(self.fd, None)


class Connection:
    def __init__(self, sock: socket.socket, scheduler: Any, on_data: Callable[[bytes], Any],
                 on_close: Callable[[], Any], max_buffer: int = 1 << 20):
        sock.setblocking(False)
        self.sock = sock
        self.fd = sock.fileno()
        self.scheduler = scheduler
        self.on_data = on_data
        self.on_close = on_close
        self.outbox = Outbox(scheduler, self.fd, sock.send, self._stop_writing, max_buffer)
        self.closed = False
        self.write_failed = False
        scheduler.add_reader(self.fd, self._readable)

    def _readable(self) -> None:
        try:
            data = self.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            log.debug("connection %d: %s", self.fd, exc)
            self.close()
            return
        if not data:
            self.close()
            return
        self.on_data(data)

    def hung_up(self) -> bool:
        """Whether the peer has closed (or reset) the connection, though the loop has not read that yet:
        a listener at its limit of clients asks before it refuses a newcomer for a place already free."""
        try:
            return self.sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            return True

    def write(self, data: bytes) -> bool:
        """Queue ``data``; False (nothing queued) if the connection is closed or its buffer is full."""
        if self.closed or self.write_failed:
            return False
        return self.outbox.write(data)

    def _stop_writing(self, exc: OSError) -> None:
        log.debug("connection %d: cannot write any more: %s", self.fd, exc)
        self.write_failed = True
        self.outbox.clear()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self.outbox.clear()
        self.scheduler.remove_reader(self.fd)
        try:
            self.sock.close()
        except OSError:
            pass
        self.on_close()


def somaxconn() -> int:
    """The kernel's largest accept backlog (a burst of clients connecting at once is not refused)."""
    try:
        with open("/proc/sys/net/core/somaxconn") as handle:
            return max(16, int(handle.read().strip()))
    except (OSError, ValueError):
        return socket.SOMAXCONN


def listen_unix(path: str, backlog: int | None = None, group: int | None = None, mode: int = 0o660) -> socket.socket:
    """Bind a Unix stream socket at ``path`` for the daemon's user and group only (``mode``, and
    ``group`` when given), replacing a stale file but never a live server.

    The socket file is created under a umask that already excludes others, so there is no moment at
    which anyone else could connect; the runtime directory (0750) keeps them out as well."""
    import os

    if os.path.lexists(path):
        probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            probe.connect(path)
        except OSError:
            os.unlink(path)  # nobody answers: left over from a crash
        else:
            raise OSError(f"{path} is in use by a running hilgate")
        finally:
            probe.close()
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    old = os.umask(0o777 & ~mode)
    try:
        sock.bind(path)
    except OSError:
        sock.close()
        raise
    finally:
        os.umask(old)
    try:
        os.chmod(path, mode)
        if group is not None:
            os.chown(path, -1, group)
        sock.listen(backlog if backlog is not None else somaxconn())
    except OSError:
        sock.close()
        raise
    sock.setblocking(False)
    return sock


def refuse(sock: socket.socket, answer: bytes) -> None:
    """Tell a client why it cannot stay (one message, sent without waiting for it) and close."""
    try:
        sock.setblocking(False)
        sock.send(answer)
    except OSError:
        pass
    sock.close()


class Listener:
    """Accepts connections on a listening socket and hands each to ``on_accept``."""

    def __init__(self, sock: socket.socket, scheduler: Any, on_accept: Callable[[socket.socket], Any],
                 path: str | None = None):
        self.sock = sock
        self.scheduler = scheduler
        self.on_accept = on_accept
        self.path = path
        scheduler.add_reader(sock.fileno(), self._accept)

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                log.warning("accept failed: %s", exc)
                return
            self.on_accept(conn)

    def close(self) -> None:
        import os

        self.scheduler.remove_reader(self.sock.fileno())
        self.sock.close()
        if self.path:
            try:
                os.unlink(self.path)
            except OSError:
                pass
