"""Hosts for a benchmark on one machine: network namespaces joined by one switch, as root.

Daemons of several hosts on loopback share one network stack and one port space; in namespaces each has
its own (its own loopback, its own address, Zenoh's TCP through a veth pair and a bridge), which is
what separate computers on a lab switch give them short of the wire.  Nothing is added to the
machine's own namespace: the bridge is in a namespace of its own, each veth pair is made with its ends
already in their namespaces, and deleting the namespaces removes everything.  Without root (or
without ``ip``) :func:`why_not` says why, and the benchmark falls back to loopback and says so.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid

SUBNET = "10.77.0"


def why_not() -> str | None:
    """Why namespaces cannot be made here (None: they can)."""
    if os.geteuid() != 0:
        return "not root"
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2)"
    return None


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


class Namespaces:
    """``count`` namespaces, host ``i`` at ``address(i)`` on one bridged /24; :meth:`command` runs a
    command in one (``ip netns exec``: the same process, so its id and CPU time are the command's).
    Removed on :meth:`close` (also when making them failed half-way)."""

    def __init__(self, count: int):
        self.tag = f"hgs{uuid.uuid4().hex[:6]}"
        self.names = [f"{self.tag}-{i}" for i in range(count)]
        self.switch = f"{self.tag}-sw"
        self.made: list[str] = []
        try:
            self._add(self.switch)
            _ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
            _ip("-n", self.switch, "link", "set", "br0", "up")
            for i, name in enumerate(self.names):
                self._add(name)
                _ip("link", "add", f"p{i}", "netns", self.switch, "type", "veth", "peer", "name", "eth0", "netns", name)
                _ip("-n", self.switch, "link", "set", f"p{i}", "master", "br0")
                _ip("-n", self.switch, "link", "set", f"p{i}", "up")
                _ip("-n", name, "addr", "add", f"{self.address(i)}/24", "dev", "eth0")
                _ip("-n", name, "link", "set", "eth0", "up")
                _ip("-n", name, "link", "set", "lo", "up")
        except BaseException:
            self.close()
            raise

    def _add(self, name: str) -> None:
        _ip("netns", "add", name)
        self.made.append(name)

    @staticmethod
    def address(i: int) -> str:
        return f"{SUBNET}.{i + 1}"

    def command(self, i: int) -> tuple[str, ...]:
        return ("ip", "netns", "exec", self.names[i])

    def close(self) -> None:
        for name in reversed(self.made):
            subprocess.run(["ip", "netns", "del", name], capture_output=True)
        self.made = []

    def __enter__(self) -> "Namespaces":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
