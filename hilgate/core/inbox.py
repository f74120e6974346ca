"""Messages from other threads (Zenoh calls back on its own) to the loop, in bounded batches.

``scheduler.post`` keeps whatever it is given, and each post writes a wake-up: a peer that sends a
hundred thousand messages a second would cost a wake-up each and as much memory as it likes.  An
:class:`Inbox` holds at most ``limit`` items (and ``max_bytes`` of them); past that it drops and counts,
and it posts one wake-up for everything that came while the loop was busy.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any, Callable

__all__ = ["Inbox"]


class Inbox:
    """``put`` from any thread; ``handle(items, dropped)`` runs on the loop with all that came."""

    __slots__ = ("post", "handle", "limit", "max_bytes", "bytes", "items", "dropped", "posted", "lock")

    def __init__(self, post: Callable[..., Any], handle: Callable[[list[Any], int], Any], limit: int,
                 max_bytes: int = 1 << 62):
        self.post = post
        self.handle = handle
        self.limit = limit
        self.max_bytes = max_bytes
        self.bytes = 0
        self.items: deque = deque()
        self.dropped = 0
        self.posted = False
        self.lock = threading.Lock()

    def put(self, item: Any, size: int = 0) -> bool:
        """False (and counted) when the inbox is full."""
        with self.lock:
            taken = len(self.items) < self.limit and self.bytes + size <= self.max_bytes
            if taken:
                self.items.append((item, size))
                self.bytes += size
            else:
                self.dropped += 1
            wake, self.posted = not self.posted, True
        if wake:
            self.post(self._drain)
        return taken

    def _drain(self) -> None:
        with self.lock:
            items, self.items = self.items, deque()
            dropped, self.dropped = self.dropped, 0
            self.bytes = 0
            self.posted = False
        self.handle([item for item, _ in items], dropped)
