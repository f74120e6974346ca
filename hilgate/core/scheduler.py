"""The event core: a heap of ``[time, sequence, callback, args]`` and a loop that pops and fires.

Ties at one time fire in the order they were scheduled (the sequence number), which is what makes
a virtual-time run reproducible bit for bit.  A handle is the heap entry itself; cancelling blanks
its callback and the loop skips it, so cancel is O(1).

:class:`VirtualScheduler` runs as fast as the CPU allows (``hilgate sim``, tests).  The real-time
scheduler of the daemon (``hilgate.realtime``) is a subclass that waits for the wall clock between
events; the models cannot tell them apart.
"""

from __future__ import annotations

import itertools
from heapq import heappop, heappush
from typing import Any, Callable

__all__ = ["VirtualScheduler"]


class VirtualScheduler:
    def __init__(self, start: float = 0.0):
        self._now = float(start)
        self._heap: list[list[Any]] = []
        self._sequence = itertools.count()
        self.events = 0

    def now(self) -> float:
        return self._now

    def at(self, t: float, fn: Callable[..., Any], *args: Any) -> list[Any]:
        if t < self._now:
            t = self._now
        entry = [t, next(self._sequence), fn, args]
        heappush(self._heap, entry)
        return entry

    def after(self, delay: float, fn: Callable[..., Any], *args: Any) -> list[Any]:
        return self.at(self._now + delay, fn, *args)

    def cancel(self, handle: list[Any] | None) -> None:
        if handle is not None:
            handle[2] = None

    def defer(self, fn: Callable[..., Any]) -> None:
        """Run ``fn()`` after the events due now (in virtual time: at once, nothing waits)."""
        fn()

    def run(self, until: float = float("inf")) -> int:
        """Fire every event up to and including ``until``; the clock then reads ``until`` (if finite)."""
        heap = self._heap
        fired = 0
        while heap:
            entry = heap[0]
            t = entry[0]
            if t > until:
                break
            heappop(heap)
            fn = entry[2]
            if fn is None:
                continue
            self._now = t
            fn(*entry[3])
            fired += 1
        if until != float("inf") and until > self._now:
            self._now = until
        self.events += fired
        return fired
