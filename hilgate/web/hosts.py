"""Which names the web view answers to: its own, never another web site's (DNS rebinding).

A web site can make its own name point at 127.0.0.1 for a moment (DNS rebinding): its page then talks
to the view as the same origin in the browser's eyes, Origin and Host both saying ``evil.example``, so
the WebSocket's Origin check alone lets it through to the challenge (issue 37 item 5).  What such a
page cannot change is the name in its address, which the browser sends as Host.  So the view answers
only to names that are its own, and refuses every other request (403) before the page, the scripts
or the challenge:

- an address literal (no DNS: nothing to rebind): the address it is bound to; any loopback address
  when it listens on loopback; any address when it listens on all of them (``0.0.0.0``, ``::``);
- ``localhost`` and names under ``.localhost`` (browsers keep them on loopback), when it listens on
  loopback or on all addresses;
- the machine's host name (``socket.gethostname()``: no DNS lookup), and the name ``--web NAME:PORT``
  gave.

The port in Host is not looked at: a tunnel (``ssh -L 9000:127.0.0.1:8080``) changes it.  A request
without Host (HTTP/1.0, not a browser) is no rebinding and is answered.  Sans-I/O.
"""

from __future__ import annotations

import ipaddress
import socket

__all__ = ["HostNames", "host_of"]


def host_of(header: str) -> str:
    """The name or address of a Host header, lower case, without its port or a final dot."""
    header = header.strip().lower()
    if header.startswith("["):
        return header[1:].partition("]")[0]
    name, colon, port = header.rpartition(":")
    if colon and (port.isdigit() or not port) and ":" not in name:
        header = name
    return header.rstrip(".") if header not in (".", "") else header


def _address(text: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        ip = ipaddress.ip_address(text.split("%", 1)[0])
    except ValueError:
        return None
    return ip.ipv4_mapped if ip.version == 6 and ip.ipv4_mapped is not None else ip


class HostNames:
    """The names a view bound to ``bound`` (``--web``'s address or name) answers to; see the module."""

    def __init__(self, bound: str, hostname: str | None = None):
        self.bound_ip = _address(bound)
        bound_name = None if self.bound_ip is not None else host_of(bound)
        loopback = bound_name == "localhost" or (self.bound_ip is not None and self.bound_ip.is_loopback)
        self.every_address = self.bound_ip is not None and self.bound_ip.is_unspecified
        self.loopback = loopback
        self.localhost = loopback or self.every_address
        names = {host_of(hostname if hostname is not None else socket.gethostname())}
        if bound_name:
            names.add(bound_name)
        self.names = frozenset(name for name in names if name)
        self.any_literal = bound_name is not None and not loopback  # a name: its addresses are unknown here

    def allows(self, header: str | None) -> bool:
        """Whether a request with this Host header is for the view (None: no Host header)."""
        if header is None:
            return True
        host = host_of(header)
        if not host:
            return False
        ip = _address(host)
        if ip is not None:
            if self.every_address or self.any_literal:
                return True
            return ip.is_loopback if self.loopback else ip == self.bound_ip
        if self.localhost and (host == "localhost" or host.endswith(".localhost")):
            return True
        return host in self.names

    def describe(self) -> str:
        """What a refused request is told: the names to use instead."""
        names = ["its address"] + (["localhost"] if self.localhost else []) + sorted(self.names)
        return ", ".join(names)
