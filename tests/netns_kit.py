"""Two hosts of their own on one machine, as root: network namespaces joined by a veth pair.

Daemons on loopback share one network stack: a link cannot be cut between them.  In namespaces each has
its own stack and address, and Zenoh's TCP goes through a veth pair that a test sets down and up (there
is no netem or iptables on these machines: a link down, a daemon stopped or killed are the faults).
Nothing is made in the machine's own namespace: the pair is created with its ends already in theirs,
so deleting the namespaces removes everything.  Names carry this process's id and a random part (other
runs share the machine); the namespaces are deleted on :meth:`HostPair.close` (a fixture's finalizer,
whatever the test did), at exit, and by the next run when a run was killed before either.

Elsewhere (not root, no ``ip``) :func:`why_not` says why, and the tests skip saying so.
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import subprocess
import uuid

PREFIX = "hgt"
NAME = re.compile(rf"{PREFIX}(\d+)x[0-9a-f]+[ab]")
SUBNET = "10.236.0"


def why_not() -> str | None:
    """Why namespaces cannot be made here (None: they can)."""
    if os.geteuid() != 0:
        return "making network namespaces and veth pairs needs root (ip netns add, ip link add type veth)"
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) to make network namespaces"
    probe = f"{PREFIX}{os.getpid()}x{uuid.uuid4().hex[:6]}a"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"`ip netns add` refused: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


def remove_stale() -> list[str]:
    """Delete the namespaces of this kit whose run is gone (killed before it could); returns their names."""
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    stale = []
    for line in listed.splitlines():
        name = line.split()[0] if line.split() else ""
        match = NAME.fullmatch(name)
        if match and not os.path.exists(f"/proc/{match.group(1)}"):
            subprocess.run(["ip", "netns", "del", name], capture_output=True)
            stale.append(name)
    return stale


class HostPair:
    """Namespaces ``a`` and ``b`` at :attr:`addresses` (``10.236.0.1``, ``.2``), joined by one veth pair
    (``eth0`` in each).  :meth:`launch` is the command prefix that runs a process in one; :meth:`cut`
    and :meth:`heal` set the link down and up."""

    def __init__(self):
        remove_stale()
        tag = f"{PREFIX}{os.getpid()}x{uuid.uuid4().hex[:8]}"
        self.names = {"a": f"{tag}a", "b": f"{tag}b"}
        self.addresses = {"a": f"{SUBNET}.1", "b": f"{SUBNET}.2"}
        self.made: list[str] = []
        atexit.register(self.close)
        try:
            for side in "ab":
                _ip("netns", "add", self.names[side])
                self.made.append(self.names[side])
            _ip("link", "add", "eth0", "netns", self.names["a"], "type", "veth", "peer", "name", "eth0",
                "netns", self.names["b"])
            for side in "ab":
                _ip("-n", self.names[side], "addr", "add", f"{self.addresses[side]}/24", "dev", "eth0")
                _ip("-n", self.names[side], "link", "set", "eth0", "up")
                _ip("-n", self.names[side], "link", "set", "lo", "up")
        except BaseException:
            self.close()
            raise

    def launch(self, side: str) -> tuple[str, ...]:
        """``ip netns exec NAME``: it execs, so the process started is the command itself (its pid, its signals)."""
        return ("ip", "netns", "exec", self.names[side])

    def cut(self) -> None:
        _ip("-n", self.names["a"], "link", "set", "eth0", "down")

    def heal(self) -> None:
        _ip("-n", self.names["a"], "link", "set", "eth0", "up")

    def close(self) -> None:
        for name in reversed(self.made):
            subprocess.run(["ip", "netns", "del", name], capture_output=True)
        self.made = []
