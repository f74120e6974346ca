"""systemd's notify protocol (``Type=notify``), spoken directly: one datagram per state change.

No dependency on libsystemd: the protocol is a Unix datagram of ``KEY=value`` lines to the socket in
``$NOTIFY_SOCKET`` (a path, or an abstract name starting with ``@``).  Outside systemd it does nothing.

Sending never blocks.  The daemon's loop calls this, and a notify socket whose reader has stopped
reading (its queue holds only a few datagrams) would otherwise freeze every link; a notification
that cannot be sent at once is dropped, counted in :data:`dropped` and logged once per run of drops.
"""

from __future__ import annotations

import logging
import os
import socket

log = logging.getLogger(__name__)

dropped = 0
"""Notifications that could not be sent without blocking (the reader is not reading)."""

_warned = False


def notify(*lines: str) -> bool:
    global dropped, _warned
    address = os.environ.get("NOTIFY_SOCKET")
    if not address:
        return False
    if address.startswith("@"):
        address = "\0" + address[1:]
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC | socket.SOCK_NONBLOCK) as sock:
            sock.sendto("\n".join(lines).encode(), address)
        _warned = False
        return True
    except (BlockingIOError, InterruptedError):
        dropped += 1
        if not _warned:
            _warned = True
            log.warning("sd_notify to %s would block (nobody reads it): notifications are dropped", address)
        return False
    except OSError as exc:
        dropped += 1
        log.warning("sd_notify to %s failed: %s", address, exc)
        return False


def watchdog_interval() -> float | None:
    """Seconds between WATCHDOG=1 pings (half systemd's timeout), or None when not asked for."""
    usec = os.environ.get("WATCHDOG_USEC")
    pid = os.environ.get("WATCHDOG_PID")
    if not usec or (pid and pid != str(os.getpid())):
        return None
    try:
        return int(usec) / 2e6
    except ValueError:
        return None
