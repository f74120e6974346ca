"""Messages from other threads (Zenoh calls back on its own) to the loop: bounded, in turns, a batch at a time.

``scheduler.post`` keeps whatever it is given, and each post writes a wake-up: a peer that sends a
hundred thousand messages a second would cost a wake-up each and as much memory as it likes.  An
:class:`Inbox` keeps each source's messages (a host's, say) in a queue of its own, at most ``limit``
of them and ``max_bytes`` of their bytes, and drops and counts beyond, per source, so that the loop
can say whose were lost; it posts one wake-up for everything that came while the loop was busy.

The loop takes at most ``batch`` messages per wake-up, one of each source in turn, and posts itself
again for the rest: one source's flood neither holds the others' messages back nor keeps the loop
from its other inputs (the control socket, the links) for longer than one batch takes.  (The hand-over
of the others' transmissions had no bound at all: a host's key flooding 60 kB messages that took the
loop longer to refuse than Zenoh's thread to hand over grew the daemon by gigabytes.)
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any, Callable

__all__ = ["Inbox", "OTHERS"]

OTHERS = "*"
"""The source under which drops are counted once ``max_sources`` sources have lost messages already."""


class Inbox:
    """``put`` from any thread; ``handle(items, dropped)`` runs on the loop with a batch of what came
    (each source's in its order) and ``dropped``, each source's count of messages dropped since the
    last batch (only sources that lost some)."""

    __slots__ = ("post", "handle", "limit", "max_bytes", "total_bytes", "batch", "max_sources", "queues", "sizes",
                 "size", "turns", "dropped", "posted", "lock")

    def __init__(self, post: Callable[..., Any], handle: Callable[[list[Any], dict[str, int]], Any], limit: int,
                 max_bytes: int = 1 << 62, total_bytes: int = 1 << 62, batch: int = 256, max_sources: int = 64):
        self.post = post
        self.handle = handle
        self.limit = limit  # messages a source may have waiting
        self.max_bytes = max_bytes  # bytes (as ``put`` says) a source may have waiting …
        self.total_bytes = total_bytes  # … and every source together
        self.batch = batch
        self.max_sources = max_sources
        self.queues: dict[str, deque] = {}  # source → its (message, size) waiting: only sources with some
        self.sizes: dict[str, int] = {}  # source → the bytes of its messages waiting
        self.size = 0  # the bytes of every source's
        self.turns: deque[str] = deque()  # the sources with messages, in the order of their next turn
        self.dropped: dict[str, int] = {}
        self.posted = False
        self.lock = threading.Lock()

    def put(self, item: Any, size: int = 0, source: str = "", make: Callable[[Any], Any] | None = None) -> bool:
        """Keep ``item`` (``make(item)`` if given: called only when there is room, so a message that is
        dropped is never copied) for the loop; False, and counted, when ``source`` has ``limit`` messages
        or ``max_bytes`` waiting already (or the sources together ``total_bytes``, or ``max_sources``
        other sources have messages waiting)."""
        with self.lock:
            queue = self.queues.get(source)
            if self.size + size > self.total_bytes:
                taken = False
            elif queue is None:
                taken = len(self.queues) < self.max_sources and self.limit > 0 and size <= self.max_bytes
            else:
                taken = len(queue) < self.limit and self.sizes[source] + size <= self.max_bytes
            if taken:
                if queue is None:
                    queue = self.queues[source] = deque()
                    self.sizes[source] = 0
                    self.turns.append(source)
                queue.append((make(item) if make is not None else item, size))
                self.sizes[source] += size
                self.size += size
            else:
                who = source if source in self.dropped or len(self.dropped) < self.max_sources else OTHERS
                self.dropped[who] = self.dropped.get(who, 0) + 1
            wake, self.posted = not self.posted, True
        if wake:
            self.post(self._drain)
        return taken

    def _drain(self) -> None:
        """On the loop: a batch, one message of each source in turn; the rest at the loop's next turn."""
        items = []
        with self.lock:
            queues, sizes, turns, batch = self.queues, self.sizes, self.turns, self.batch
            while turns and len(items) < batch:
                source = turns.popleft()
                queue = queues[source]
                item, size = queue.popleft()
                items.append(item)
                self.size -= size
                if queue:
                    sizes[source] -= size
                    turns.append(source)
                else:
                    del queues[source], sizes[source]
            dropped, self.dropped = self.dropped, {}
            self.posted = more = bool(turns)
        if more:
            self.post(self._drain)  # (after the loop's other inputs: the loop runs only what was posted before)
        self.handle(items, dropped)
