"""Real-time scheduling of the same model code: events fire when the wall clock reaches them.

One thread runs everything.  :class:`RealtimeScheduler` is three parts around one core:

- the timer core of :class:`~hilgate.core.scheduler.VirtualScheduler` (``fire_due``: the same heap, the
  same order, deferred calls at the same point, one guard for a failing callback);
- the wait policy (:mod:`hilgate.core.waiting`): the spin before a timer, the linger after an input;
- the I/O loop (:mod:`hilgate.core.ioloop`): descriptors, calls from other threads, signals.

What stays here is the wall clock and how the three meet.  Sub-millisecond lateness without burning a
core comes from the loop sleeping in ``select()`` on the epoll descriptor (``epoll_wait`` rounds to whole
milliseconds), the thread's timer slack lowered from the default 50 µs with
``prctl(PR_SET_TIMERSLACK)``, the wait policy's spin and linger, and Python's automatic garbage
collection off while the loop runs (a collection takes up to a millisecond at an arbitrary moment): the
loop collects the young generations itself when the next event is at least ``gc_gap_s`` away; the
models make no reference cycles per event, so reference counting frees nearly everything anyway.

What remains is the kernel: on a shared 2-core machine a normal process is sometimes preempted
for milliseconds.  ``hilgate run --realtime`` (:mod:`hilgate.core.priority`: SCHED_RR for the loop
thread alone where the host allows it, else the lowest niceness it allows; the systemd unit allows it)
removes most of that.

Timers fire with the model clock set to their exact scheduled time (lateness is visible as the
difference with :meth:`model_time`), so the models compute the same times as in virtual time.  Input
from a descriptor is stamped with the model time at which it is read, never earlier: before an input
is handled, every timer already due fires first, at its own time.  (Stamping input with an overdue
timer's time instead would back-date it: after a preemption, a frame an application sent after
another frame had arrived would be placed on air while that frame was still arriving, and collide
with it in the model although it never did.)  When the loop was late as it read an input, by how
much is kept in :attr:`input_lateness` for the trace: the input may have waited up to that long.
Lateness is seen only when the loop is awake to see it (a deadline passed while it waited, or time
spent away from its descriptors): a part that must know when its input came (an emulated serial line,
which judges a byte's arrival against a modem's buffer) asks the loop to look at least every few
milliseconds (:meth:`watch_inputs`), and :meth:`input_window` then says how long before the clock's
reading the input may have been ready: a frozen machine (a virtual machine's host busy with its disk,
a preemption, SIGSTOP) is seen as such, not taken for a writer that wrote everything at once.
``speed`` K runs the model at K times real time.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import os
import select
import time
from typing import Any, Callable

from .ioloop import IoLoop
from .scheduler import INF, VirtualScheduler
from .stall import HostStall
from .waiting import AdaptiveWait

log = logging.getLogger(__name__)

PR_SET_TIMERSLACK = 29
LONGEST_WAIT_S = 0.5  # the loop looks at the clock at least this often (wall seconds), unless asked to more
WALL_LATE_S = 0.002  # a wall-clock timer this late lets the inputs ready by then be read first


def lower_timer_slack(nanoseconds: int = 1000) -> bool:
    """Ask Linux to wake this thread within ``nanoseconds`` of a timeout (default slack: 50 µs)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_TIMERSLACK, nanoseconds, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def make_realtime(priority: int) -> str:
    """The calling thread at real-time priority ``priority`` where allowed (:func:`priority.raise_priority`);
    what it got, for the log."""
    from .priority import raise_priority

    return raise_priority(priority).describe()


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
    def __init__(self, speed: float = 1.0, gc_gap_s: float = 0.002, wait: AdaptiveWait | None = None):
        super().__init__()
        if speed <= 0:
            raise ValueError("speed must be positive")
        self.speed = speed
        self.gc_gap_s = gc_gap_s
        self.wait = wait if wait is not None else AdaptiveWait(now=time.perf_counter())
        self.io = IoLoop()
        self._origin: float | None = None
        self._running = False
        self._watch_end = 0.0  # model time at which the loop last stopped watching its descriptors
        self.input_lateness = 0.0
        """Model seconds by which the loop was late when it read the input being handled (0 if on time)."""
        self.late_threshold = 0.0005
        self.watch_s = LONGEST_WAIT_S
        """The longest the loop waits before it looks at the clock again (wall seconds): :meth:`watch_inputs`."""
        self._watchers: list[list[float]] = []
        self._stall: HostStall | None = None  # opened when first asked
        self.epoch_ns = 0
        """The UNIX clock (ns) at model time 0, once the clock runs: how hosts relate their model times."""

    # -- time ---------------------------------------------------------------------------------

    def start_clock(self) -> None:
        """Model time 0 is now (called by :meth:`run` if nobody did it before)."""
        if self._origin is None:
            wall_ns, counter = paired_clocks()
            self._origin = counter - self.now() / self.speed
            self.epoch_ns = wall_ns - round(self.now() / self.speed * 1e9)

    def after_wall(self, seconds: float, fn: Callable[..., Any], *args: Any) -> list[Any]:
        """``fn(*args)`` ``seconds`` of wall clock after the wall clock's reading, not after :meth:`now`:
        a timer that fired late holds the clock at its own due time, and a driver pacing its serial
        writes from it would write the next piece early by that lateness (a burst that overflows a modem
        without flow control), a timeout would end early.  (The model's own timers keep :meth:`after`.)

        Such a timer that comes due while the loop is late (it was frozen, or busy) runs only once the
        inputs ready by then are read: a device's answer that came in time, but was not read because the
        whole machine stood still, is not taken for a device that did not answer."""
        t = self.model_time() if self._origin is not None else self._now
        entry = self.at((t if t > self._now else self._now) + seconds * self.speed, self._wall_due)
        entry[3] = (entry, fn, args)
        return entry

    def _wall_due(self, entry: list[Any], fn: Callable[..., Any], args: tuple) -> None:
        if self.model_time() - self._now > WALL_LATE_S * self.speed:
            self.io.post(self._wall_after_inputs, entry, fn, args)
        else:
            fn(*args)

    @staticmethod
    def _wall_after_inputs(entry: list[Any], fn: Callable[..., Any], args: tuple) -> None:
        if entry[2] is not None:  # (not cancelled meanwhile: an answer read just before may have done that)
            fn(*args)

    def model_time(self) -> float:
        """Where the wall clock is, in model seconds."""
        if self._origin is None:
            return self.now()
        return (time.perf_counter() - self._origin) * self.speed

    def _failed(self, fn: Callable[..., Any]) -> None:
        log.exception("callback %r failed", fn)  # one broken callback must not stop the daemon

    # -- inputs: the I/O loop's (the Loop interface) ------------------------------------------------

    def add_reader(self, fd: int, callback: Callable[[], Any]) -> None:
        self.io.add_reader(fd, callback)

    def remove_reader(self, fd: int) -> None:
        self.io.remove_reader(fd)

    def set_writer(self, fd: int, callback: Callable[[], Any] | None) -> None:
        self.io.set_writer(fd, callback)

    def post(self, fn: Callable[..., Any], *args: Any) -> None:
        self.io.post(fn, *args)

    def on_signal(self, signum: int, handler: Callable[[int], Any]) -> None:
        self.io.on_signal(signum, handler)

    def watch_inputs(self, every_s: float) -> list[float]:
        handle = [every_s]
        self._watchers.append(handle)
        self.watch_s = min(LONGEST_WAIT_S, *(h[0] for h in self._watchers))
        return handle

    def unwatch_inputs(self, handle: Any) -> None:
        if handle in self._watchers:
            self._watchers.remove(handle)
        self.watch_s = min([LONGEST_WAIT_S] + [h[0] for h in self._watchers])

    def input_window(self) -> float:
        """The input being handled was ready at most this long before :meth:`now` (model seconds): the
        lateness the loop saw, plus what it cannot see, the longest it waits without looking at the clock
        (a machine frozen during a shorter wait, or a wake-up delayed by other processes, is within it)."""
        return self.input_lateness + (self.watch_s + self.late_threshold) * self.speed

    def host_stall(self) -> float | None:
        if self._stall is None:
            self._stall = HostStall()
        return self._stall.seconds()

    def stop(self) -> None:
        self._running = False
        self.io.post(lambda: None)

    def close(self) -> None:
        self.io.close()
        if self._stall is not None:
            self._stall.close()

    # -- the loop -------------------------------------------------------------------------------

    def _input_time(self) -> None:
        """Make the model clock read now for an input: overdue timers fire first, at their own times,
        then the clock moves to the wall clock's model time (never backwards)."""
        t = self.model_time()
        self.fire_due(t)
        self.advance(t)

    def _handle_inputs(self, timeout: float, entry: float | None = None) -> None:
        """Wait up to ``timeout`` wall seconds for input (0: only look), then handle what is ready, each
        input at its own model time.  The first input is stamped with the clock read as the wait or the
        look ended (one reading of the clock, not three: this is every frame's first step).  ``entry``:
        the model time the caller read just before, from which ``timeout`` was reckoned (None: read now)."""
        io = self.io
        if timeout > 0:
            if entry is None:
                entry = self.model_time()
            deadline = entry + io.waits_until(timeout) * self.speed
            events_ready = io.wait(timeout)  # (the ready descriptors: one system call for a long wait)
            t = self.model_time()
            blind = entry - self._watch_end  # not watching inputs since the last wait or poll ended
            self._watch_end = t
            if not events_ready and t - deadline > self.late_threshold:
                # Woke late (preempted, or stopped: after SIGCONT, epoll_wait returns EINTR and Python,
                # past the deadline, gives up with nothing): look once more at what is ready by now.
                events_ready = io.epoll.poll(0)
            if not events_ready:
                self.wait.overslept((t - deadline) / self.speed)
                return
            if t > deadline:
                blind += t - deadline  # overslept: stopped or preempted while waiting
        else:
            events_ready = io.epoll.poll(0)
            t = self.model_time()
            blind = t - self._watch_end  # (the look itself, a microsecond, counted in)
            self._watch_end = t
        posted = io.posted
        if events_ready or posted:
            self.wait.input_came(time.perf_counter(), timeout > 0)
            # Input may have waited since the loop last stopped watching its descriptors (``blind``: firing
            # timers, or a preemption between two waits), and longer if the loop overslept or timers are
            # overdue (a preemption during the wait).  That bound is kept in input_lateness; overdue
            # timers then fire first, at their own times.
            due = self.peek()
            late = t - due if t - due > blind else blind
            self.input_lateness = late if late > self.late_threshold else 0.0
            if due <= t:
                self.fire_due(t)
            elif self._deferred and due != INF and due > self._now:
                self.run_deferred()  # (what fire_due does when nothing is due: the instant is over)
            if t > self._now:  # (advance, written out)
                if self._deferred:
                    self.run_deferred()
                self._now = t
        fresh = True  # the clock was just brought to the wall clock's time: the first input needs no other
        readers, writers = io.readers, io.writers
        for fd, events in events_ready:
            if events & select.EPOLLOUT:
                if not fresh:
                    self._input_time()
                fresh = False
                writer = writers.get(fd)  # looked up after overdue timers, which may close it
                if writer is not None:
                    try:
                        writer()
                    except Exception:
                        self._failed(writer)
            if events & ~select.EPOLLOUT:
                if not fresh:
                    self._input_time()
                fresh = False
                reader = readers.get(fd)
                if reader is not None:
                    try:
                        reader()
                    except Exception:
                        self._failed(reader)
        for _ in range(len(posted)):
            # (only the calls posted before this round: one posted meanwhile, by another thread or by a
            # call itself, waits for the next round, after the descriptors; taking calls until none was
            # left kept the loop here, the control socket unanswered, for as long as a flood kept posting)
            fn, args = posted.popleft()
            self._input_time()
            try:
                fn(*args)
            except Exception:
                self._failed(fn)
        self.input_lateness = 0.0

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
        fired = 0
        policy = self.wait
        while self._running:
            now = self.model_time()
            next_t = self.peek()  # (kept: each peek and clock read is one of every input's few calls)
            while next_t <= now:  # (again: firing took time, and more became due meanwhile)
                fired += self.fire_due(now)
                now = self.model_time()
                next_t = self.peek()
            if self._deferred:
                self.run_deferred()  # the instant is over (an input's, with no timer after it yet)
                next_t = self.peek()  # (a deferred call may have set a timer)
            if now >= until:
                self.advance(until)
                break
            wait = (min(next_t, until) - now) / self.speed
            spin = policy.spin_s
            if wait > spin and not self.io.posted and not policy.keep_polling(time.perf_counter()):
                # (a posted call is never slept over: only the first of several writes a wake-up)
                self._collect_if_idle(wait)
                entry = self.model_time()  # (read once: the wait is reckoned from it, and the blind time)
                wait = (min(next_t, until) - entry) / self.speed
                self._handle_inputs(min(max(0.0, wait - spin), self.watch_s), entry)
            else:
                self._handle_inputs(0.0)
        return fired
