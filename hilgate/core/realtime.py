"""Real-time scheduling of the same model code: events fire when the wall clock reaches them.

One thread runs everything, in the manner of gpsd: the timer heap of :class:`VirtualScheduler` and
an epoll set of file descriptors (POSIX queues, sockets, serial ports, a wake-up pipe for other
threads and signals).  Three details give sub-millisecond lateness without burning a core:

- ``epoll_wait`` and asyncio round timeouts to whole milliseconds, so the loop sleeps in
  ``select()`` on the epoll descriptor itself, which takes microseconds;
- the thread's timer slack is lowered from the default 50 µs with ``prctl(PR_SET_TIMERSLACK)``;
- the sleep ends a spin before the next event and the loop polls the rest of the way.  It only
  spins in those last microseconds, so an idle daemon sleeps.  The spin adapts to how late
  ``select()`` actually wakes on this host (a peak-hold estimate that decays, between ``spin_min_s``
  and ``spin_s``): a fixed 0.3 ms made a daemon with hundreds of links and thousands of timers a
  second poll nearly all the time;
- after handling input it may keep polling for a while before it sleeps: an application that just
  sent usually sends again (or answers) soon, and waking a sleeping process costs tens of
  microseconds on a virtual machine.  The window adapts as KVM's halt polling does: it halves each
  time it expires with no input and grows (up to ``linger_s``) when input came soon after the loop
  went to sleep; and all lingering together may take at most ``linger_budget`` (half) of the wall
  clock: a fixed 0.15 ms after every input cost hundreds of links much of a core, while a tighter cap
  (10 %) added some 70 µs to every round trip of a single busy link.  Only traffic makes it spin;
- Python's automatic garbage collection is off while the loop runs (a collection takes up to a
  millisecond at an arbitrary moment); the loop collects the young generations itself when the
  next event is at least ``gc_gap_s`` away.  The models make no reference cycles per event, so
  reference counting frees nearly everything anyway.

What remains is the kernel: on a shared 2-core machine a normal process is sometimes preempted
for milliseconds.  :func:`make_realtime` (``hilgate run --realtime-priority``, or
``CPUSchedulingPolicy=fifo`` in the systemd unit) removes most of that.

Timers fire with the model clock set to their exact scheduled time (lateness is visible as the
difference with :meth:`model_time`), so the models compute the same times as in virtual time.  Input
from a descriptor is stamped with the model time at which it is read, never earlier: before an input
is handled, every timer already due fires first, at its own time.  (Stamping input with an overdue
timer's time instead would back-date it: after a preemption, a frame an application sent after
another frame had arrived would be placed on air while that frame was still arriving, and collide
with it in the model although it never did.)  When the loop was late as it read an input, by how
much is kept in :attr:`input_lateness` for the trace: the input may have waited up to that long.
``speed`` K runs the model at K times real time.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import os
import select
import signal
import time
from collections import deque
from heapq import heappop
from typing import Any, Callable

from .scheduler import VirtualScheduler

log = logging.getLogger(__name__)

PR_SET_TIMERSLACK = 29
LINGER_CREDIT_CAP = 0.005
"""Lingering saved up while idle (wall seconds): enough for a burst, not for a second of spinning."""
OVERSLEEP_DECAY = 0.02
"""Fraction by which the oversleep estimate moves down towards each smaller observation."""
LINGER_FLOOR = 0.00001
"""A linger window below this is not worth a poll: it becomes 0 (and grows back from here)."""


def lower_timer_slack(nanoseconds: int = 1000) -> bool:
    """Ask Linux to wake this thread within ``nanoseconds`` of a timeout (default slack: 50 µs)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_TIMERSLACK, nanoseconds, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def make_realtime(priority: int) -> str:
    """SCHED_FIFO at ``priority`` and all memory locked (no page faults in the loop); returns what
    could be done, for the log.  Needs CAP_SYS_NICE and RLIMIT_MEMLOCK (or root)."""
    done = []
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        done.append(f"SCHED_FIFO priority {priority}")
    except (OSError, AttributeError) as exc:
        done.append(f"no SCHED_FIFO ({exc})")
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.mlockall(1 | 2) == 0:  # MCL_CURRENT | MCL_FUTURE
            done.append("memory locked")
        else:
            done.append(f"memory not locked ({os.strerror(ctypes.get_errno())})")
    except (OSError, AttributeError):
        done.append("memory not locked")
    return ", ".join(done)


PAIRING_TRIES = 20
PAIRING_TIGHT_S = 20e-6


def paired_clocks() -> tuple[int, float]:
    """The UNIX clock (ns) and ``perf_counter`` read at one instant, as nearly as this host allows.

    Two daemons relate their model times through the UNIX clock at model time 0 (``epoch_ns``); an
    error there shifts every arrival from one host at the other.  Read one after the other, a thread
    switch or a preemption between the two reads (a loaded host, Zenoh's threads wanting the GIL)
    would put milliseconds into it.  So the UNIX clock is read between two counter reads and the
    tightest of a few tries is kept, paired with the middle of its bracket."""
    best: tuple[float, int, float] | None = None
    for _ in range(PAIRING_TRIES):
        before = time.perf_counter()
        wall_ns = time.time_ns()
        after = time.perf_counter()
        width = after - before
        if best is None or width < best[0]:
            best = (width, wall_ns, (before + after) / 2.0)
        if width <= PAIRING_TIGHT_S:
            break
    return best[1], best[2]


class RealtimeScheduler(VirtualScheduler):
    adaptive = True
    """False: the fixed spin and linger of earlier versions (``benchmarks/many_links.py --spin fixed``)."""

    def __init__(self, speed: float = 1.0, spin_s: float = 0.0003, gc_gap_s: float = 0.002,
                 linger_s: float = 0.00015, spin_min_s: float = 0.00005, linger_budget: float = 0.5):
        super().__init__()
        if speed <= 0:
            raise ValueError("speed must be positive")
        self.speed = speed
        self.spin_s = spin_s
        """The spin before the next timer now (wall seconds); adapted between spin_min_s and spin_max_s."""
        self.spin_max_s = spin_s
        self.spin_min_s = min(spin_min_s, spin_s)
        self._oversleep = spin_s / 2  # how late select() wakes here: a peak-hold estimate (wall seconds)
        self.gc_gap_s = gc_gap_s
        self.linger_s = linger_s
        self._linger = linger_s  # the linger window now (wall seconds), adapted in [0, linger_s]
        self.linger_budget = linger_budget
        self._linger_credit = LINGER_CREDIT_CAP  # wall seconds of lingering still allowed
        self._credit_time = time.perf_counter()
        self._lingering = False  # polling after an input, in its linger window
        self._last_input = -1.0
        self._origin: float | None = None
        self._epoll = select.epoll()
        self._readers: dict[int, Callable[[], Any]] = {}
        self._writers: dict[int, Callable[[], Any]] = {}
        self._registered: set[int] = set()
        self._posted: deque[tuple[Callable[..., Any], tuple[Any, ...]]] = deque()
        self._wake_r, self._wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        self.add_reader(self._wake_r, self._drain_wakeups)
        self._running = False
        self._signals: dict[int, Callable[[int], Any]] = {}
        self._fired = 0
        self._watch_end = 0.0  # model time at which the loop last stopped watching its descriptors
        self.input_lateness = 0.0
        """Model seconds by which the loop was late when it read the input being handled (0 if on time)."""
        self.late_threshold = 0.0005
        self.epoch_ns = 0
        """The UNIX clock (ns) at model time 0, once the clock runs: how hosts relate their model times."""

    # -- time ---------------------------------------------------------------------------------

    def start_clock(self) -> None:
        """Model time 0 is now (called by :meth:`run` if nobody did it before)."""
        if self._origin is None:
            wall_ns, counter = paired_clocks()
            self._origin = counter - self.now() / self.speed
            self.epoch_ns = wall_ns - round(self.now() / self.speed * 1e9)

    def model_time(self) -> float:
        """Where the wall clock is, in model seconds."""
        if self._origin is None:
            return self.now()
        return (time.perf_counter() - self._origin) * self.speed

    # -- inputs ---------------------------------------------------------------------------------

    def add_reader(self, fd: int, callback: Callable[[], Any]) -> None:
        """Call ``callback()`` in the loop whenever ``fd`` is readable (or hung up)."""
        self._readers[fd] = callback
        self._update(fd)

    def remove_reader(self, fd: int) -> None:
        if self._readers.pop(fd, None) is not None:
            self._update(fd)

    def set_writer(self, fd: int, callback: Callable[[], Any] | None) -> None:
        """Call ``callback()`` whenever ``fd`` can take more output; None stops watching."""
        if callback is None:
            if self._writers.pop(fd, None) is None:
                return
        else:
            self._writers[fd] = callback
        self._update(fd)

    def _update(self, fd: int) -> None:
        mask = (select.EPOLLIN if fd in self._readers else 0) | (select.EPOLLOUT if fd in self._writers else 0)
        try:
            if not mask:
                if fd in self._registered:
                    self._registered.discard(fd)
                    self._epoll.unregister(fd)
            elif fd in self._registered:
                self._epoll.modify(fd, mask)
            else:
                self._epoll.register(fd, mask)
                self._registered.add(fd)
        except (OSError, ValueError):
            self._registered.discard(fd)  # already closed: the kernel forgot it

    def post(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)`` in the loop as soon as possible; safe from other threads and signal handlers."""
        self._posted.append((fn, args))
        try:
            os.write(self._wake_w, b"\0")
        except BlockingIOError:
            pass  # the pipe is full of wake-ups already

    def on_signal(self, signum: int, handler: Callable[[int], Any]) -> None:
        """Handle ``signum`` in the loop (not in the interrupted frame)."""
        self._signals[signum] = handler
        signal.signal(signum, lambda s, _frame: self.post(self._signals[s], s))

    def _drain_wakeups(self) -> None:
        try:
            while os.read(self._wake_r, 4096):
                pass
        except BlockingIOError:
            pass

    def stop(self) -> None:
        self._running = False
        self.post(lambda: None)

    def close(self) -> None:
        for fd in list(self._readers):
            self.remove_reader(fd)
        for fd in list(self._writers):
            self.set_writer(fd, None)
        self._epoll.close()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    # -- the loop -------------------------------------------------------------------------------

    def _begin_inputs(self, blind: float) -> None:
        """The loop is about to read input.  Input may have waited since the loop last stopped
        watching its descriptors (``blind``: firing timers, or a preemption between two waits), and
        longer if the loop overslept or timers are overdue (a preemption during the wait).  That
        bound is kept in :attr:`input_lateness`; overdue timers then fire first, at their own times."""
        t = self.model_time()
        late = max(blind, t - self.peek())
        self.input_lateness = late if late > self.late_threshold else 0.0
        self._input_time()

    def _input_time(self) -> None:
        """Make the model clock read now for an input: overdue timers fire first, at their own times,
        then the clock moves to the wall clock's model time (never backwards)."""
        t = self.model_time()
        self._fire_due(t)
        self.advance(t)

    def _fire_due(self, now: float) -> None:
        """Fire every timer due at or before ``now``, each at its own time.  (``peek`` and ``step``
        written out: every frame through the daemon passes here two or three times.)"""
        heap = self._heap
        while heap:
            entry = heap[0]
            t = entry[0]
            if t > now:
                return
            heappop(heap)
            fn = entry[2]
            if fn is None:  # cancelled
                continue
            self._now = t
            self.events += 1
            self._fired += 1
            try:
                fn(*entry[3])
            except Exception:  # one broken timer must not stop the daemon
                log.exception("callback %r failed", fn)

    def _fire(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
        try:
            fn(*args)
        except Exception:  # one broken timer must not stop the daemon
            log.exception("callback %r failed", fn)

    def _handle_inputs(self, timeout: float) -> None:
        entry = self.model_time()
        blind = entry - self._watch_end  # not watching inputs since the last wait or poll ended
        if timeout > 0:
            deadline = entry + timeout * self.speed
            try:
                ready, _, _ = select.select([self._epoll.fileno()], [], [], timeout)
            except InterruptedError:  # pragma: no cover - PEP 475 retries, kept for safety
                ready = True
            woke = self.model_time()
            self._watch_end = woke
            if not ready:
                if self.adaptive:
                    self._learn_oversleep((woke - deadline) / self.speed)
                return
            blind += max(0.0, woke - deadline)  # overslept: stopped or preempted while waiting
        events_ready = self._epoll.poll(0)
        if timeout <= 0:
            self._watch_end = self.model_time()
        if events_ready or self._posted:
            now = time.perf_counter()
            if self.adaptive:
                self._input_came(now, timeout > 0)
            self._last_input = now
            self._begin_inputs(blind)
        fresh = True  # the clock was just brought to the wall clock's time: the first input needs no other
        for fd, events in events_ready:
            if events & select.EPOLLOUT:
                if not fresh:
                    self._input_time()
                fresh = False
                writer = self._writers.get(fd)  # looked up after overdue timers, which may close it
                if writer is not None:
                    self._call(writer)
            if events & ~select.EPOLLOUT:
                if not fresh:
                    self._input_time()
                fresh = False
                reader = self._readers.get(fd)
                if reader is not None:
                    self._call(reader)
        posted = self._posted
        while posted:
            fn, args = posted.popleft()
            self._input_time()
            try:
                fn(*args)
            except Exception:
                log.exception("posted call %r failed", fn)
        self.input_lateness = 0.0

    # -- adaptive spinning ----------------------------------------------------------------------

    def _learn_oversleep(self, late: float) -> None:
        """A sleep ended ``late`` wall seconds after its deadline: the spin before timers follows the
        upper envelope of these (at once upwards, slowly downwards); a preemption of milliseconds
        counts as ``spin_max_s``, since no spin would have hidden it."""
        late = min(max(late, 0.0), self.spin_max_s)
        estimate = self._oversleep
        estimate = late if late > estimate else estimate - (estimate - late) * OVERSLEEP_DECAY
        self._oversleep = estimate
        self.spin_s = min(self.spin_max_s, max(self.spin_min_s, 1.5 * estimate + 0.00002))

    def _input_came(self, now: float, after_sleep: bool) -> None:
        """Input is ready: pay the linger that led to it, and grow the window if the loop had gone to
        sleep just before (a longer linger would have caught it)."""
        self._refill(now)
        gap = now - self._last_input
        if self._lingering:
            self._linger_credit -= gap  # polled since the last input, and it paid off
            self._lingering = False
        elif after_sleep and gap <= self.linger_s and self._linger < gap:
            self._linger = min(self.linger_s, max(2 * self._linger, LINGER_FLOOR, gap))

    def _linger_now(self, now: float) -> bool:
        """Whether to keep polling after the last input instead of sleeping."""
        since = now - self._last_input
        if not self.adaptive:
            return since <= self.linger_s
        if since <= self._linger and (self._lingering or self._linger_credit > 0):
            self._lingering = True
            return True
        if self._lingering:  # the window expired with no input: it was not worth it
            self._lingering = False
            self._refill(now)
            self._linger_credit -= since
            self._linger = 0.0 if self._linger < 2 * LINGER_FLOOR else self._linger / 2
        return False

    def _refill(self, now: float) -> None:
        self._linger_credit = min(LINGER_CREDIT_CAP,
                                  self._linger_credit + (now - self._credit_time) * self.linger_budget)
        self._credit_time = now

    def _call(self, callback: Callable[[], Any]) -> None:
        try:
            callback()
        except Exception:  # one broken input must not stop the daemon
            log.exception("handler %r failed", callback)

    def run(self, until: float = float("inf")) -> int:
        """Run until :meth:`stop` or until model time ``until``; returns the number of timer events."""
        lower_timer_slack()
        self.start_clock()
        self._running = True
        self._watch_end = self.model_time()
        gc_was_enabled = gc.isenabled()
        gc.disable()
        try:
            fired = self._loop(until)
        finally:
            if gc_was_enabled:
                gc.enable()
        return fired

    def _collect_if_idle(self, wait: float) -> None:
        """Collect garbage now if the next event is far enough away and there is garbage to look at."""
        if wait < self.gc_gap_s:
            return
        young, middle, old = gc.get_count()
        threshold0, threshold1, threshold2 = gc.get_threshold()
        if old > threshold2 and wait > 10 * self.gc_gap_s:
            gc.collect(2)
        elif middle > threshold1:
            gc.collect(1)
        elif young > threshold0:
            gc.collect(0)

    def _loop(self, until: float) -> int:
        self._fired = 0
        while self._running:
            now = self.model_time()
            if self.peek() <= now:
                self._fire_due(now)
                now = self.model_time()
                while self.peek() <= now:  # firing took time: what became due meanwhile
                    self._fire_due(now)
                    now = self.model_time()
            if self._deferred:
                self.run_deferred()
            if now >= until:
                self.advance(until)
                break
            next_t = self.peek()
            wait = (min(next_t, until) - now) / self.speed
            spin = self.spin_s
            if wait > spin and not self._linger_now(time.perf_counter()):
                self._collect_if_idle(wait)
                wait = (min(next_t, until) - self.model_time()) / self.speed
                self._handle_inputs(min(max(0.0, wait - spin), 0.5))
            else:
                self._handle_inputs(0.0)
        return self._fired
