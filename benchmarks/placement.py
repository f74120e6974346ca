"""Where a latency benchmark's processes run: pinned, so that its anchor and hilgate draw the same lot.

On a virtual machine a message between two processes on one CPU costs a context switch; between two
CPUs it wakes an idle virtual CPU, several times dearer (8 µs against 50 µs for a bare POSIX-queue
ping-pong on this project's 2-core machine).  Left to the kernel, a benchmark draws one of these per
run, and its anchor may draw the other: the difference between the two is then a lottery.  So every
process of a latency measurement is pinned (``os.sched_setaffinity``) and both placements are measured:

- **same CPU**: every process on the first CPU this benchmark may use;
- **across CPUs**: the processes along a message's path alternate between the first two, so every hop
  crosses (application on CPU a, daemon on CPU b, the echoing application on CPU a, ...).

Only the CPUs of ``os.sched_getaffinity(0)`` are used; with one, "across CPUs" is not run.  A process
is pinned at its start, before it makes any thread (a Zenoh session's threads, a daemon's), so all of
its threads stay where it is: :func:`pin` at the top of a ``multiprocessing`` target,
:func:`pinned_command` around a command line (the pin survives ``exec``).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass

TRAMPOLINE = "import os, sys; os.sched_setaffinity(0, {int(sys.argv[1])}); os.execvp(sys.argv[2], sys.argv[2:])"


@dataclass(frozen=True)
class Placement:
    """One way of placing a message's path on the CPUs: step ``i`` of the path runs on :meth:`cpu`."""

    name: str
    cpus: tuple[int, ...]

    def cpu(self, step: int) -> int:
        return self.cpus[step % len(self.cpus)]

    def describe(self, roles: list[str]) -> str:
        """Which role runs where, e.g. "client, echo on CPU 0; daemon on CPU 1" for the path's steps
        ``roles`` ["client", "daemon", "echo"]."""
        where: dict[int, list[str]] = {}
        for step, role in enumerate(roles):
            where.setdefault(self.cpu(step), []).append(role)
        return "; ".join(f"{', '.join(names)} on CPU {cpu}" for cpu, names in sorted(where.items()))


def placements() -> tuple[list[Placement], str | None]:
    """Same CPU and, with two CPUs or more, across CPUs; and why across is not run, if it is not."""
    cpus = sorted(os.sched_getaffinity(0))
    same = Placement("same CPU", (cpus[0],))
    if len(cpus) < 2:
        return [same], f"across CPUs: not run ({len(cpus)} CPU)"
    return [same, Placement("across CPUs", (cpus[0], cpus[1]))], None


def choose(which: str) -> tuple[list[Placement], str | None]:
    """``--placement same|across|both``: the placements to run, and why one asked for is not run."""
    every, why_not = placements()
    chosen = [p for p in every if which == "both" or p.name.startswith(which)]
    if which == "same":
        why_not = None
    return chosen, why_not


def pin(cpu: int | None) -> None:
    """Pin the calling thread, and every thread and process it makes from now on, to ``cpu`` (None: leave it)."""
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})


@contextlib.contextmanager
def pinned(cpu: int | None) -> Iterator[None]:
    """The calling thread on ``cpu`` for the block, back where it was after it."""
    before = os.sched_getaffinity(0)
    pin(cpu)
    try:
        yield
    finally:
        os.sched_setaffinity(0, before)


def pinned_command(argv: list[str], cpu: int | None) -> list[str]:
    """``argv`` started on ``cpu`` (None: unchanged): a Python one-liner pins itself and ``exec``s it, so
    the process id is the command's and none of its threads starts elsewhere."""
    if cpu is None:
        return argv
    return [sys.executable, "-c", TRAMPOLINE, str(cpu), *argv]
