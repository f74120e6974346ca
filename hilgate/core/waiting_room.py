"""Who waits at a door to prove the token, and who makes room when too many do.

A door that authenticates (the TCP GLI, the web view) must keep the connections that have not proved
the token yet, and it must bound them: each costs a descriptor and memory, and a stranger can open as
many as it likes.  The bound must not become the stranger's weapon (issue 37): refusing the newcomer
when the table is full lets whoever filled it first keep everyone out, for as long as it keeps filling
it.  So the newcomer is always let in, and the place it needs is taken from the connection that has
waited longest **of the source that holds the most** places:

- a flood from one source makes room from itself (a source holds at most ``per_source`` places: its
  next connection closes its own oldest);
- a flood spread over many sources makes room from the largest of them;
- an honest client holds one place for one round trip (it proves the token at once), so it is the
  newest of a source that holds little: a stranger must open, during that round trip, as many
  connections as the table holds to reach it, and would have to do so again for the next one.

The connection that waited longest has had the most time to prove the token; closing the newest
instead (or refusing it) is what lets a slowloris keep its places.  A deadline for the whole
handshake (the door's) bounds how long any place is held at all.

A source is an IPv4 address, or an IPv6 /64: one host's share of a network, whose addresses cost it
nothing.  Sans-I/O: the door closes the connections :meth:`WaitingRoom.admit` names.
"""

from __future__ import annotations

import ipaddress
import itertools
from typing import Hashable

__all__ = ["WaitingRoom", "source_of"]


def source_of(address: str) -> str:
    """The source ``address`` counts for: itself (IPv4, or an IPv4-mapped IPv6), or its IPv6 /64."""
    try:
        ip = ipaddress.ip_address(address.split("%", 1)[0])
    except ValueError:
        return address  # not an IP (a Unix socket's empty name): its own source
    if ip.version == 6:
        if ip.ipv4_mapped is not None:
            return str(ip.ipv4_mapped)
        return str(ipaddress.ip_network(f"{ip}/64", strict=False))
    return str(ip)


class WaitingRoom:
    """At most ``per_source`` connections of one source and ``total`` in all wait; see the module."""

    def __init__(self, total: int = 64, per_source: int = 8):
        if not 1 <= per_source <= total:
            raise ValueError("need 1 <= per_source <= total")
        self.total = total
        self.per_source = per_source
        self._order = itertools.count()
        self._sources: dict[str, dict[Hashable, int]] = {}  # source -> {key: arrival}, oldest first
        self._source_of: dict[Hashable, str] = {}

    def __len__(self) -> int:
        return len(self._source_of)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._source_of

    def waiting(self, address: str) -> int:
        """How many of ``address``'s source wait now."""
        return len(self._sources.get(source_of(address), ()))

    def admit(self, key: Hashable, address: str) -> list[Hashable]:
        """Let ``key`` (a connection from ``address``) in; the keys that must make room for it, which
        have left the room already (the door closes them)."""
        source = source_of(address)
        evicted = []
        if len(self._sources.get(source, ())) >= self.per_source:
            evicted.append(self._evict(source))
        elif len(self) >= self.total:
            evicted.append(self._evict(self._largest()))
        self._sources.setdefault(source, {})[key] = next(self._order)
        self._source_of[key] = source
        return evicted

    def leave(self, key: Hashable) -> bool:
        """``key`` proved the token or went away (False: it was not waiting, e.g. already evicted)."""
        source = self._source_of.pop(key, None)
        if source is None:
            return False
        members = self._sources[source]
        del members[key]
        if not members:
            del self._sources[source]
        return True

    def _largest(self) -> str:
        """The source holding the most places; of equals, the one whose oldest came first."""
        return max(self._sources, key=lambda s: (len(self._sources[s]), -next(iter(self._sources[s].values()))))

    def _evict(self, source: str) -> Hashable:
        key = next(iter(self._sources[source]))  # dicts keep insertion order: the oldest first
        self.leave(key)
        return key
