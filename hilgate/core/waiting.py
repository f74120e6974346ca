"""How the real-time loop waits: when to sleep, when to spin before a timer, when to keep polling after
an input.  A policy of its own, asked by the loop (:mod:`hilgate.core.realtime`) and fed the times it
saw; it never reads a clock itself, so a test drives it with given times.

- The sleep ends a *spin* before the next timer and the loop polls the rest of the way.  It only spins
  in those last microseconds, so an idle daemon sleeps.  The spin adapts to how late ``select()``
  actually wakes on this host (a peak-hold estimate that decays, between ``spin_min_s`` and
  ``spin_max_s``): a fixed 0.3 ms made a daemon with hundreds of links and thousands of timers a second
  poll nearly all the time.
- After an input it may keep polling for a while (it *lingers*) before it sleeps: an application that
  just sent usually sends again (or answers) soon, and waking a sleeping process costs tens of
  microseconds on a virtual machine.  The window adapts as KVM's halt polling does: it halves each time
  it expires with no input and grows (up to ``linger_s``) when input came soon after the loop went to
  sleep; and all lingering together may take at most ``linger_budget`` (half) of the wall clock: a fixed
  0.15 ms after every input cost hundreds of links much of a core, while a tighter cap (10 %) added
  some 70 µs to every round trip of a single busy link.  Only traffic makes it spin.
"""

from __future__ import annotations

LINGER_CREDIT_CAP = 0.005
"""Lingering saved up while idle (wall seconds): enough for a burst, not for a second of spinning."""
OVERSLEEP_DECAY = 0.02
"""Fraction by which the oversleep estimate moves down towards each smaller observation."""
LINGER_FLOOR = 0.00001
"""A linger window below this is not worth a poll: it becomes 0 (and grows back from here)."""


class AdaptiveWait:
    """The spin before timers and the linger after inputs, each adapted to what the loop saw."""

    def __init__(self, spin_s: float = 0.0003, linger_s: float = 0.00015, spin_min_s: float = 0.00005,
                 linger_budget: float = 0.5, now: float = 0.0):
        self.spin_s = spin_s
        """The spin before the next timer now (wall seconds); adapted between spin_min_s and spin_max_s."""
        self.spin_max_s = spin_s
        self.spin_min_s = min(spin_min_s, spin_s)
        self.oversleep = spin_s / 2  # how late select() wakes here: a peak-hold estimate (wall seconds)
        self.linger_s = linger_s
        self.linger = linger_s  # the linger window now (wall seconds), adapted in [0, linger_s]
        self.linger_budget = linger_budget
        self.credit = LINGER_CREDIT_CAP  # wall seconds of lingering still allowed
        self.credit_time = now
        self.lingering = False  # polling after an input, in its linger window
        self.last_input = -1.0

    def overslept(self, late: float) -> None:
        """A sleep ended ``late`` wall seconds after its deadline: the spin before timers follows the
        upper envelope of these (at once upwards, slowly downwards); a preemption of milliseconds
        counts as ``spin_max_s``, since no spin would have hidden it."""
        late = min(max(late, 0.0), self.spin_max_s)
        estimate = self.oversleep
        estimate = late if late > estimate else estimate - (estimate - late) * OVERSLEEP_DECAY
        self.oversleep = estimate
        self.spin_s = min(self.spin_max_s, max(self.spin_min_s, 1.5 * estimate + 0.00002))

    def input_came(self, now: float, after_sleep: bool) -> None:
        """Input is ready at wall time ``now``: pay the linger that led to it, and grow the window if the
        loop had gone to sleep just before (a longer linger would have caught it)."""
        self.credit = min(LINGER_CREDIT_CAP, self.credit + (now - self.credit_time) * self.linger_budget)
        self.credit_time = now  # (refill written out: every input passes here)
        gap = now - self.last_input
        if self.lingering:
            self.credit -= gap  # polled since the last input, and it paid off
            self.lingering = False
        elif after_sleep and gap <= self.linger_s and self.linger < gap:
            self.linger = min(self.linger_s, max(2 * self.linger, LINGER_FLOOR, gap))
        self.last_input = now

    def keep_polling(self, now: float) -> bool:
        """Whether to keep polling after the last input instead of sleeping, at wall time ``now``."""
        since = now - self.last_input
        if since <= self.linger and (self.lingering or self.credit > 0):
            self.lingering = True
            return True
        if self.lingering:  # the window expired with no input: it was not worth it
            self.lingering = False
            self.refill(now)
            self.credit -= since
            self.linger = 0.0 if self.linger < 2 * LINGER_FLOOR else self.linger / 2
        return False

    def refill(self, now: float) -> None:
        self.credit = min(LINGER_CREDIT_CAP, self.credit + (now - self.credit_time) * self.linger_budget)
        self.credit_time = now
