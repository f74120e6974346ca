"""The real-time loop's inputs, in the manner of gpsd: one epoll set of descriptors (POSIX queues,
sockets, serial ports), calls posted from other threads and signal handlers, and a wake-up pipe that
ends a wait when one is posted.  It knows nothing of time: :mod:`hilgate.core.realtime` says how long
to wait and dispatches what is ready, stamping each input with the model clock."""

from __future__ import annotations

import os
import select
import signal
from collections import deque
from typing import Any, Callable

WAKE_READ = 4096
"""Bytes of wake-ups read from the pipe at once."""
EPOLL_WAIT_MIN_S = 0.002
"""From this wait on (seconds), the loop sleeps in one ``epoll_wait`` of whole milliseconds instead of
``select()`` then ``epoll_wait(0)``: it may wake up to a millisecond early, which matters no more."""


class IoLoop:
    def __init__(self) -> None:
        self.epoll = select.epoll()
        self.readers: dict[int, Callable[[], Any]] = {}
        self.writers: dict[int, Callable[[], Any]] = {}
        self._registered: set[int] = set()
        self.posted: deque[tuple[Callable[..., Any], tuple[Any, ...]]] = deque()
        self._signals: dict[int, Callable[[int], Any]] = {}
        self._wake_r, self._wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        self.add_reader(self._wake_r, self._drain_wakeups)

    def add_reader(self, fd: int, callback: Callable[[], Any]) -> None:
        """Call ``callback()`` in the loop whenever ``fd`` is readable (or hung up)."""
        self.readers[fd] = callback
        self._update(fd)

    def remove_reader(self, fd: int) -> None:
        if self.readers.pop(fd, None) is not None:
            self._update(fd)

    def set_writer(self, fd: int, callback: Callable[[], Any] | None) -> None:
        """Call ``callback()`` whenever ``fd`` can take more output; None stops watching."""
        if callback is None:
            if self.writers.pop(fd, None) is None:
                return
        else:
            self.writers[fd] = callback
        self._update(fd)

    def _update(self, fd: int) -> None:
        mask = (select.EPOLLIN if fd in self.readers else 0) | (select.EPOLLOUT if fd in self.writers else 0)
        try:
            if not mask:
                if fd in self._registered:
                    self._registered.discard(fd)
                    self.epoll.unregister(fd)
            elif fd in self._registered:
                self.epoll.modify(fd, mask)
            else:
                self.epoll.register(fd, mask)
                self._registered.add(fd)
        except (OSError, ValueError):
            self._registered.discard(fd)  # already closed: the kernel forgot it

    def post(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)`` in the loop as soon as possible; safe from other threads and signal handlers.

        Only the call that finds the queue of posted calls empty writes a wake-up: until the loop has
        taken every call, one already written stands for the rest.  (Appending and counting are each
        atomic under the GIL.  The loop takes, each round, the calls posted before the round; it never
        sleeps while calls are waiting, so a call appended meanwhile is either left for its next round
        or finds the queue empty and wakes it.)"""
        posted = self.posted
        posted.append((fn, args))
        if len(posted) == 1:
            try:
                os.write(self._wake_w, b"\0")
            except BlockingIOError:
                pass  # the pipe is full of wake-ups already

    def on_signal(self, signum: int, handler: Callable[[int], Any]) -> None:
        """Handle ``signum`` in the loop (not in the interrupted frame)."""
        self._signals[signum] = handler
        signal.signal(signum, lambda s, _frame: self.post(self._signals[s], s))

    def _drain_wakeups(self) -> None:
        """Empty the wake-up pipe: a read that returns less than it asked for has taken everything
        (no second read that fails, and its exception, per wake-up)."""
        try:
            while len(os.read(self._wake_r, WAKE_READ)) == WAKE_READ:
                pass
        except BlockingIOError:
            pass

    def wait(self, timeout: float) -> list[tuple[int, int]]:
        """Sleep until a descriptor is ready or ``timeout`` seconds passed; the ready descriptors and
        their events (empty: none came).

        ``epoll_wait`` counts its timeout in whole milliseconds, so a wait shorter than
        :data:`EPOLL_WAIT_MIN_S` sleeps in ``select()`` on the epoll descriptor (microseconds) and then
        asks epoll what is ready: two system calls.  A longer one (an idle daemon, the wait for the next
        frame of an application) is one ``epoll_wait`` of the whole milliseconds it holds, so it wakes
        up to a millisecond early, never late; the loop then waits for the rest."""
        if timeout >= EPOLL_WAIT_MIN_S:
            return self.epoll.poll((int(timeout * 1000.0) - 0.5) / 1000.0)  # (Python rounds this up to the ms)
        try:
            ready, _, _ = select.select([self.epoll.fileno()], [], [], timeout)
        except InterruptedError:  # pragma: no cover - PEP 475 retries, kept for safety
            return self.epoll.poll(0)
        return self.epoll.poll(0) if ready else []

    @staticmethod
    def waits_until(timeout: float) -> float:
        """How long :meth:`wait` sleeps at most for ``timeout`` (seconds): whole milliseconds from
        :data:`EPOLL_WAIT_MIN_S` on, else ``timeout`` itself."""
        return float(int(timeout * 1000.0)) / 1000.0 if timeout >= EPOLL_WAIT_MIN_S else timeout

    def close(self) -> None:
        for fd in list(self.readers):
            self.remove_reader(fd)
        for fd in list(self.writers):
            self.set_writer(fd, None)
        self.epoll.close()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
