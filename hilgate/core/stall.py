"""How long tasks on this host have waited for a CPU, for memory or for I/O: Linux's pressure stall
information (``/proc/pressure``, PSI).

The kernel hands a pseudo-terminal's bytes to its reader through a worker thread of its own
(``flush_to_ldisc``), an ordinary task: on a busy machine it waits for a CPU like any other, and the
bytes reach the reader late although the reader was awake and looking (tens of milliseconds beside
CPU-bound neighbours, seen here, more beside a disk writer that syncs).  Nothing tells the reader; but
no task can have waited longer than the time during which *some* task waited, which PSI counts (the
``some`` line's ``total``, microseconds, since boot).  So the difference of two readings bounds, from
above, the delay the kernel may have added between them: 0 on a quiet host.

One ``pread`` per file (about a microsecond): cheap enough for every read of a serial line, too dear
for every frame of the loop.  Where PSI is missing (a kernel built without it, ``psi=0``, some
containers) :meth:`HostStall.seconds` is None and the caller falls back to a fixed allowance.
"""

from __future__ import annotations

import logging
import os

log = logging.getLogger(__name__)

PRESSURE = ("/proc/pressure/cpu", "/proc/pressure/memory", "/proc/pressure/io")


def some_total_us(text: bytes) -> int:
    """The ``some`` line's ``total=`` of one pressure file's text (microseconds)."""
    for line in text.splitlines():
        if line.startswith(b"some "):
            return int(line.rsplit(b"total=", 1)[1])
    raise ValueError("no 'some' line")


class HostStall:
    """The host's cumulative stall time (seconds), from the pressure files it could open."""

    def __init__(self, paths: tuple[str, ...] = PRESSURE):
        self.fds: list[int] = []
        for path in paths:
            try:
                fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
            except OSError:
                continue
            try:
                some_total_us(os.pread(fd, 256, 0))
            except (OSError, ValueError):
                os.close(fd)
                continue
            self.fds.append(fd)
        if not self.fds:
            log.info("no pressure stall information on this host (/proc/pressure): serial lines of emulated "
                     "modems judge their input with a fixed allowance")

    def seconds(self) -> float | None:
        """Seconds some task waited (CPU, memory and I/O summed: a bound from above), or None without PSI."""
        if not self.fds:
            return None
        total = 0
        for fd in self.fds:
            try:
                total += some_total_us(os.pread(fd, 256, 0))
            except (OSError, ValueError):
                return None
        return total / 1e6

    def close(self) -> None:
        for fd in self.fds:
            os.close(fd)
        self.fds = []
