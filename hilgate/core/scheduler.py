"""The event core: a heap of ``[time, sequence, callback, args]`` and a loop that pops and fires.

Ties at one time fire in the order they were scheduled (the sequence number), which is what makes
a virtual-time run reproducible bit for bit.  A handle is the heap entry itself; cancelling blanks
its callback and the loop skips it, so cancel is O(1).

:class:`VirtualScheduler` is the core (:meth:`fire_due`) and virtual time: it runs as fast as the CPU
allows (``hilgate sim``, tests).  The real-time scheduler of the daemon (:mod:`hilgate.core.realtime`)
fires its timers with the same :meth:`fire_due` and only adds the wall clock, a wait policy and the
I/O loop; the models cannot tell them apart.  Two clocks, one meaning for every call:

- :meth:`at` / :meth:`after` are model time;
- :meth:`after_wall` is wall-clock seconds (model seconds × ``speed`` in real time, reckoned from the
  wall clock's reading, not from a late timer's due time; the same as :meth:`after` in virtual time,
  where ``speed`` is 1): for what the operator or a device waits for (timeouts, retries, periodic
  flushes, a serial line's pacing), never for the model;
- :meth:`defer` runs a call once the events due at the current instant have all fired, before the
  clock moves on (to a later timer, or to an input's time in real time), in both clocks.

A callback that raises stops a virtual-time run (a test sees it); the daemon logs it and goes on
(:meth:`VirtualScheduler._failed`, the one guard, for timers, deferred calls and inputs alike).
"""

from __future__ import annotations

import itertools
from heapq import heappop, heappush
from typing import Any, Callable, Protocol

from ..models.clock import Clock

__all__ = ["Scheduler", "Loop", "VirtualScheduler"]

INF = float("inf")


class Scheduler(Clock, Protocol):
    """What the daemon's parts (doors, drivers, emulators, the router) ask of the scheduler, in either
    clock: the models' :class:`~hilgate.models.clock.Clock` and the calls below."""

    speed: float
    """Model seconds per wall-clock second (``--speed``; 1 in virtual time)."""
    input_lateness: float
    """How late (model seconds) the loop read the input being handled; 0 when on time or virtual."""
    epoch_ns: int
    """The UNIX clock (ns) at model time 0 once the clock runs (0 in virtual time)."""

    def after(self, delay: float, fn: Callable[..., Any], *args: Any) -> Any: ...

    def after_wall(self, seconds: float, fn: Callable[..., Any], *args: Any) -> Any: ...

    def defer(self, fn: Callable[[], Any]) -> None: ...

    def watch_inputs(self, every_s: float) -> Any: ...

    def unwatch_inputs(self, handle: Any) -> None: ...

    def input_window(self) -> float: ...

    def host_stall(self) -> float | None: ...


class Loop(Scheduler, Protocol):
    """The real-time scheduler's input side: descriptors, calls from other threads, signals."""

    def add_reader(self, fd: int, callback: Callable[[], Any]) -> None: ...

    def remove_reader(self, fd: int) -> None: ...

    def set_writer(self, fd: int, callback: Callable[[], Any] | None) -> None: ...

    def post(self, fn: Callable[..., Any], *args: Any) -> None: ...

    def on_signal(self, signum: int, handler: Callable[[int], Any]) -> None: ...

    def stop(self) -> None: ...


class VirtualScheduler:
    """The timer core of both clocks, and virtual time: :meth:`run` fires every event as fast as the
    CPU allows (``hilgate sim``, tests).  The real-time scheduler (:mod:`hilgate.core.realtime`) is this
    class with a wall clock, a wait and an I/O loop around :meth:`fire_due`; the models cannot tell them
    apart."""

    speed = 1.0
    """Model seconds per wall-clock second (the real-time scheduler's ``--speed``; 1 in virtual time)."""
    input_lateness = 0.0
    """How late the loop read the input being handled (model seconds): always 0 in virtual time."""
    epoch_ns = 0
    """The UNIX clock (ns) at model time 0: 0 in virtual time, which has no wall clock."""

    def __init__(self, start: float = 0.0):
        self._now = float(start)
        self._heap: list[list[Any]] = []
        self._sequence = itertools.count()
        self._deferred: list[Callable[[], Any]] = []
        self.defer = self._deferred.append  # (the list's own append: every READY defers, one Python call fewer)
        self.events = 0

    # -- how well an input's time is known ------------------------------------------------------

    def watch_inputs(self, every_s: float) -> Any:
        """Ask that the loop look at its inputs at least every ``every_s`` wall seconds, so that
        :meth:`input_window` is that tight (a real-time concern: nothing to do in virtual time, where an
        input is handled at its exact time); the handle is for :meth:`unwatch_inputs`."""
        return None

    def unwatch_inputs(self, handle: Any) -> None:
        pass

    def input_window(self) -> float:
        """How long before :meth:`now` (model seconds) the input being handled may have been ready to
        read: 0 in virtual time."""
        return 0.0

    def host_stall(self) -> float | None:
        """Seconds that tasks on this host have waited for a CPU, memory or I/O so far (None: unknown): a
        bound on what the kernel may have delayed meanwhile (:mod:`hilgate.core.stall`).  Nothing waits
        in virtual time."""
        return 0.0

    # -- the clock ------------------------------------------------------------------------------

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

    def after_wall(self, seconds: float, fn: Callable[..., Any], *args: Any) -> list[Any]:
        """Call ``fn(*args)`` after ``seconds`` of wall-clock time."""
        return self.at(self._now + seconds * self.speed, fn, *args)

    def cancel(self, handle: list[Any] | None) -> None:
        if handle is not None:
            handle[2] = None

    def defer(self, fn: Callable[[], Any]) -> None:  # type: ignore[no-redef]  # (replaced per instance)
        """Call ``fn()`` once the events due now have all fired (used to coalesce notifications, such
        as READY/BUSY, that would otherwise flip within one instant).  Each scheduler replaces this
        method with its deferred list's own ``append`` (``__init__``): the same, without a Python call."""
        self._deferred.append(fn)

    def advance(self, t: float) -> None:
        """Move the clock to ``t`` for something that is not a timer (input read at ``t``); never back.
        The instant being left is over: its deferred calls run first."""
        if t > self._now:
            if self._deferred:
                self.run_deferred()
            self._now = t

    # -- the core: the next event, every event due, the deferred calls ----------------------------

    def peek(self) -> float:
        """Time of the next event (cancelled ones are dropped), or infinity."""
        heap = self._heap
        while heap and heap[0][2] is None:
            heappop(heap)
        return heap[0][0] if heap else INF

    def fire_due(self, until: float) -> int:
        """Fire every event due at or before ``until``, each at its own time, in the order scheduled;
        the deferred calls of an instant run once its events have all fired, before the clock moves on.
        Returns how many fired.  Both clocks run their timers here: it is the simulator's hot path."""
        heap = self._heap
        deferred = self._deferred
        if deferred and heap and heap[0][0] > self._now:
            self.run_deferred()  # the instant in which they were deferred (an input's) is over
        fired = 0
        while heap:
            entry = heap[0]
            t = entry[0]
            if t > until:
                break
            heappop(heap)
            fn = entry[2]
            if fn is None:  # cancelled
                continue
            self._now = t
            fired += 1
            try:
                fn(*entry[3])
            except Exception:
                self._failed(fn)
            if deferred and (not heap or heap[0][0] > t):
                self.run_deferred()
        self.events += fired
        return fired

    def run_deferred(self) -> None:
        deferred = self._deferred  # one list for the scheduler's life: fire_due keeps a local name for it
        while deferred:
            batch = deferred[:]
            deferred.clear()
            for fn in batch:
                try:
                    fn()
                except Exception:
                    self._failed(fn)

    def _failed(self, fn: Callable[..., Any]) -> None:
        """A callback raised (called in its ``except``): in virtual time the run stops with it, so a
        test or ``hilgate sim`` shows the error where it happened.  The daemon logs it and goes on.
        Timers, deferred calls, inputs and posted calls all end here (each ``except Exception`` around
        them is written out where it is, not behind a call: they are the per-frame path)."""
        raise  # noqa: PLE0704  (the exception being handled)

    # -- virtual time ------------------------------------------------------------------------------

    def run(self, until: float = INF) -> int:
        """Fire every event up to and including ``until``; the clock then reads ``until`` (if finite)."""
        fired = self.fire_due(until)
        if self._deferred:
            self.run_deferred()
        if until != INF and until > self._now:
            self._now = until
        return fired
