"""The only view of time the models have.

``models/`` never reads the wall clock or sleeps: it asks a :class:`Clock` for the current time and
to call it back later.  ``hilgate.core.scheduler`` provides a virtual-time implementation (as fast as
possible, for ``hilgate sim`` and tests) and a real-time one (for the daemon); both run this code
unchanged.
"""

from __future__ import annotations

from typing import Any, Callable, Protocol


class Clock(Protocol):
    def now(self) -> float:
        """Model time of the event being handled, in seconds since the start of the run."""

    def at(self, t: float, fn: Callable[..., Any], *args: Any) -> Any:
        """Call ``fn(*args)`` at model time ``t`` (never earlier than now); returns a handle."""

    def cancel(self, handle: Any) -> None:
        """Forget a call made with :meth:`at` that has not fired yet."""
