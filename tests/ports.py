"""Loopback ports for a test's daemons, outside the kernel's ephemeral range.

A port found by binding port 0 comes from the ephemeral range (``ip_local_port_range``, 32768–60999 by
default), the very range the kernel gives every outgoing connection: between the probe closing it and the
daemon binding it, another worker's Zenoh session or client may be given it as its own end (CI saw a Zenoh
TLS listener refused "Address already in use" so). Ports below the range are never handed out by the kernel;
they are taken only by whoever asks for one by number, and a probe bind tells whether someone has.
"""

from __future__ import annotations

import random
import socket

LOWEST = 20000  # above the well-known and most registered services a lab's PC may run
_given: set[int] = set()  # never twice in one process: a port just closed may linger in TIME_WAIT


def _ephemeral_low() -> int:
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as limits:
            return int(limits.read().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def _free(port: int) -> bool:
    """Whether ``port`` can be bound now for both TCP and UDP (a daemon may want either on it)."""
    for probe_kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
        with socket.socket(socket.AF_INET, probe_kind) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                return False
    return True


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A loopback port free now that no outgoing connection can be given meanwhile (TCP by default,
    ``socket.SOCK_DGRAM`` for UDP); each call in a process gets another. Where the ephemeral range leaves
    no room below it, a port from the kernel as before."""
    high = _ephemeral_low()
    if high - LOWEST < 1000:
        with socket.socket(socket.AF_INET, kind) as probe:
            probe.bind(("127.0.0.1", 0))
            return probe.getsockname()[1]
    chooser = random.SystemRandom()  # two runs on one machine start from different places
    for _ in range(200):
        port = chooser.randrange(LOWEST, high)
        if port not in _given and _free(port):
            _given.add(port)
            return port
    raise RuntimeError(f"no free loopback port in {LOWEST}–{high - 1} after 200 tries")
