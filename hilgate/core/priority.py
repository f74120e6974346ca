"""The loop thread's scheduling: real-time priority where the host allows it, else the lowest niceness it
allows, and what it got, said in the log and in ``hilgate status``.

On a shared host the kernel preempts a normal process for milliseconds now and then (the video encoder,
the GUI, a disk flush's kworker); a modem's frame is then delivered late by as much.  ``hilgate run
--realtime`` asks for a real-time policy for the loop thread alone, so that the other work waits for it
and not the reverse.  The choices, and why:

- **SCHED_RR, not SCHED_FIFO.**  Neither protects normal processes from a real-time one; they differ only
  between real-time threads of equal priority, where FIFO lets one run until it blocks and RR takes turns
  every time slice.  Two daemons on one host (or ns-3 and a daemon in a benchmark) at the same priority
  then share a CPU instead of one shutting the other out for as long as it is busy.
- **A modest priority (10 by default).**  Below the kernel's interrupt threads (50 on a PREEMPT_RT kernel:
  a serial port's interrupt must run before the loop that waits for its bytes) and its own per-CPU
  threads (99).
- **The loop thread only** (``SCHED_RESET_ON_FORK``).  A thread or process made after it (Zenoh's,
  a serial reader, the scene worker, BELLHOP) starts at normal priority and nice 0: they carry bulk work
  that must not get ahead of other programs.
- **Not when the kernel does not throttle real-time threads** (``kernel.sched_rt_runtime_us = -1``).
  The loop never spins for long (:mod:`hilgate.core.waiting`: at most ``spin_max_s``, 0.3 ms, before a
  timer, and lingering after input within half the wall clock), but a real-time thread that never
  slept (a daemon overloaded, or a bug) would keep its CPU from every normal process.  The kernel's
  throttling (by default real-time threads get at most 0.95 s of every second on each CPU; since Linux
  6.12 the fair server reserves the rest for normal threads) is the guarantee that the machine stays
  usable; with it switched off, the daemon takes niceness instead and says why.
- **Memory locked only where it cannot fail later.**  ``mlockall(MCL_FUTURE)`` under a finite
  ``RLIMIT_MEMLOCK`` makes every later allocation past the limit fail (a MemoryError in the loop), so it
  is asked only when the limit is unlimited (the unit's ``LimitMEMLOCK=infinity``) or the process holds
  CAP_IPC_LOCK; with ``MCL_ONFAULT`` pages are locked as they are touched, not all at once (a Zenoh
  session's mappings would otherwise cost some 40 MB of resident memory at once).
- **Niceness, where real time is refused**: the lowest the kernel allows (``RLIMIT_NICE``, or -20 with
  CAP_SYS_NICE), tried from there upwards.
"""

from __future__ import annotations

import ctypes
import errno
import logging
import os
import resource
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger(__name__)

DEFAULT_PRIORITY = 10
"""``--realtime`` without ``--realtime-priority``: see the module's docstring."""
# (SCHED_BATCH, SCHED_IDLE and SCHED_RESET_ON_FORK are Linux's; Python names them only where the platform has them)
POLICIES = {os.SCHED_OTHER: "SCHED_OTHER", os.SCHED_FIFO: "SCHED_FIFO", os.SCHED_RR: "SCHED_RR",
            getattr(os, "SCHED_BATCH", 3): "SCHED_BATCH", getattr(os, "SCHED_IDLE", 5): "SCHED_IDLE"}  # (see above)
RESET_ON_FORK = getattr(os, "SCHED_RESET_ON_FORK", 0x40000000)  # (Linux's; see above)
CAP_IPC_LOCK, CAP_SYS_NICE = 14, 23
MCL_CURRENT, MCL_FUTURE, MCL_ONFAULT = 1, 2, 4
RT_RUNTIME = "/proc/sys/kernel/sched_rt_runtime_us"


@dataclass
class Scheduling:
    """What the loop thread runs at, and why not more: what the log and ``hilgate status`` say."""

    asked: int = 0
    """The real-time priority asked for (0: ``--realtime`` was not given)."""
    policy: str = "SCHED_OTHER"
    priority: int = 0
    nice: int = 0
    memory_locked: bool = False
    notes: list[str] = field(default_factory=list)
    """Why the loop got less than it asked for (real time refused, memory not locked)."""

    @property
    def kind(self) -> str:
        """``realtime``, ``nice`` (real time refused, a negative nice value instead) or ``normal``."""
        if self.policy in ("SCHED_RR", "SCHED_FIFO"):
            return "realtime"
        return "nice" if self.nice < 0 else "normal"

    def describe(self) -> str:
        if self.kind == "realtime":
            got = f"real-time {self.policy} priority {self.priority}"
        elif self.kind == "nice":
            got = f"not real-time: {self.policy} at nice {self.nice}"
        else:
            got = f"normal: {self.policy} at nice {self.nice}"
        got += ", memory locked" if self.memory_locked else ""
        if not self.asked:
            return got + " (--realtime not given)"
        return got + "".join(f"; {note}" for note in self.notes)

    def as_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "policy": self.policy, "priority": self.priority, "nice": self.nice,
                "memory_locked": self.memory_locked, "asked_priority": self.asked, "notes": list(self.notes),
                "text": self.describe()}


def _capabilities() -> int:
    """This process's effective capabilities (a bit mask; 0 where /proc says nothing)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("CapEff:"):
                    return int(line.split()[1], 16)
    except OSError:
        pass
    return 0


def _capable(capability: int) -> bool:
    return bool(_capabilities() >> capability & 1)


def _memory_locked_kb() -> int:
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmLck:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def rt_throttling() -> bool | None:
    """Whether the kernel throttles real-time threads (None: it does not say, not Linux)."""
    try:
        with open(RT_RUNTIME) as runtime:
            return int(runtime.read()) >= 0
    except (OSError, ValueError):
        return None


def _cgroup_rt_budget() -> tuple[str, int] | None:
    """The real-time budget (µs a period) of this process's cgroup v1 ``cpu`` controller, where the kernel
    schedules real-time threads by group (a group with 0 refuses them even to root): (its file, value)."""
    try:
        with open("/proc/self/cgroup") as groups:
            for line in groups:
                _, controllers, path = line.rstrip("\n").split(":", 2)
                if "cpu" in controllers.split(","):
                    for mount in (controllers, "cpu", "cpu,cpuacct"):
                        name = os.path.join("/sys/fs/cgroup", mount, path.lstrip("/"), "cpu.rt_runtime_us")
                        if os.path.exists(name):
                            with open(name) as budget:
                                return name, int(budget.read())
    except (OSError, ValueError):
        pass
    return None


def _limit_text(value: int) -> str:
    return "unlimited" if value == resource.RLIM_INFINITY else str(value)


def _realtime(priority: int) -> tuple[int, str | None]:
    """SCHED_RR for the calling thread at ``priority`` (or at the lower one RLIMIT_RTPRIO allows): the
    priority got (0: refused) and why it is not the one asked."""
    if rt_throttling() is False:
        return 0, (f"real time not taken: the kernel does not throttle real-time threads ({RT_RUNTIME} = -1), "
                   f"so a loop that never slept would keep its CPU from every other program")
    limit = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
    capable = _capable(CAP_SYS_NICE)
    chosen = priority if capable or limit == resource.RLIM_INFINITY or limit >= priority else int(limit)
    if chosen <= 0:
        return 0, f"SCHED_RR refused: RLIMIT_RTPRIO is {_limit_text(limit)} and the process lacks CAP_SYS_NICE"
    try:
        os.sched_setscheduler(0, os.SCHED_RR | RESET_ON_FORK, os.sched_param(chosen))
    except (OSError, AttributeError) as exc:
        # (an AttributeError, where the platform has no sched_setscheduler, has neither strerror nor errno)
        why = getattr(exc, "strerror", None) or str(exc)
        budget = _cgroup_rt_budget()
        refused = getattr(exc, "errno", None) == errno.EPERM  # (as above: an AttributeError has no errno)
        if refused and budget is not None and budget[1] == 0:
            why += f" (this process's cgroup has no real-time budget: {budget[0]} is 0)"
        elif refused:
            why += f" (CAP_SYS_NICE {'held' if capable else 'lacking'}, RLIMIT_RTPRIO {_limit_text(limit)})"
        return 0, f"SCHED_RR priority {chosen} refused: {why}"
    if chosen != priority:
        return chosen, f"priority {chosen}, not {priority}: RLIMIT_RTPRIO is {limit}"
    return chosen, None


def _lowest_nice() -> tuple[int, str | None]:
    """The lowest nice value the kernel lets the calling thread take, taken; and why it is not -20."""
    try:  # threads made from now on start at nice 0, not at this thread's negative value
        os.sched_setscheduler(0, os.SCHED_OTHER | RESET_ON_FORK, os.sched_param(0))
    except (OSError, AttributeError):
        pass
    now = os.getpriority(os.PRIO_PROCESS, 0)
    limit = resource.getrlimit(resource.RLIMIT_NICE)[0]
    if _capable(CAP_SYS_NICE) or limit == resource.RLIM_INFINITY:
        floor = -20
    else:
        floor = max(-20, min(20 - int(limit), now))  # RLIMIT_NICE r allows nice down to 20 - r
    for nice in range(floor, now):
        try:
            os.setpriority(os.PRIO_PROCESS, 0, nice)  # (Linux: the calling thread)
            break
        except OSError:
            continue
    got = os.getpriority(os.PRIO_PROCESS, 0)
    if got > -20:
        return got, f"nice {got} is the lowest RLIMIT_NICE ({_limit_text(limit)}) allows without CAP_SYS_NICE"
    return got, None


def _lock_memory() -> str | None:
    """Lock the process's memory as it is touched; why not, if not (None: locked)."""
    limit = resource.getrlimit(resource.RLIMIT_MEMLOCK)[0]
    if limit != resource.RLIM_INFINITY and not _capable(CAP_IPC_LOCK):
        return (f"memory not locked: RLIMIT_MEMLOCK is {limit // 1024} kB (locking future allocations under a "
                f"limit would make them fail once past it)")
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        for flags in (MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT, MCL_CURRENT | MCL_FUTURE):  # (ONFAULT: Linux 4.4)
            if libc.mlockall(flags) == 0:
                return None
            if ctypes.get_errno() != errno.EINVAL:
                break
        return f"memory not locked ({os.strerror(ctypes.get_errno())})"
    except (OSError, AttributeError) as exc:
        return f"memory not locked ({exc})"


def raise_priority(priority: int = DEFAULT_PRIORITY) -> Scheduling:
    """Give the calling thread (the loop's) real-time priority ``priority`` and lock memory, or the
    lowest niceness allowed: what it got (see the module's docstring)."""
    notes = []
    got, why = _realtime(priority)
    if why:
        notes.append(why)
    if not got:
        _, why = _lowest_nice()
        if why:
            notes.append(why)
    why = _lock_memory()
    if why:
        notes.append(why)
    return current(priority, notes)


def current(asked: int = 0, notes: list[str] | None = None) -> Scheduling:
    """The calling thread's scheduling as the kernel has it now (``asked`` and ``notes``: what was asked
    and why it was not all given, as :func:`raise_priority` found)."""
    policy = os.sched_getscheduler(0) & ~RESET_ON_FORK
    return Scheduling(asked=asked, policy=POLICIES.get(policy, str(policy)), priority=os.sched_getparam(0).sched_priority,
                      nice=os.getpriority(os.PRIO_PROCESS, 0), memory_locked=_memory_locked_kb() > 0,
                      notes=list(notes or []))
