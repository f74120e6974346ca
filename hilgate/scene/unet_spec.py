"""A link's ``unet:`` key: where its UnetStack door listens (``gli: [unet]``, :mod:`hilgate.gli.unet_door`).

``unet: {tcp: 1100}`` listens on loopback, as a real UnetStack modem's API port is reached from the
lab's computer; ``host:`` names another address of this machine to listen on (the door has no
authentication of its own, as fjåge's API has none: docs/security.md says how to restrict it), and
``protocol:`` the UnetStack protocol number the link's received frames are given (0, ``DATA``, by
default: what an unbound ``UnetSocket`` and one bound to ``DATA`` receive).
"""

from __future__ import annotations

import ipaddress
from typing import Any

from .checks import Fields, integer, text
from .yaml_nodes import Node

__all__ = ["unet_door", "listen_host", "UNET_KEYS"]

UNET_KEYS = ("tcp", "host", "protocol")
MAX_PROTOCOL = 63  # UnetStack's protocol numbers: 0 (DATA), 1-31 its own, 32 (USER) to 63


def listen_host(node: Node, path: str) -> str:
    """An IP address of this machine to listen on (or ``localhost``): not a name looked up at start."""
    value = text(node, path)
    if value == "localhost":
        return "127.0.0.1"
    try:
        return str(ipaddress.ip_address(value))
    except ValueError:
        raise node.error(path, f"{value!r} is not an IP address (e.g. 127.0.0.1 or 0.0.0.0)") from None


def unet_door(node: Node, path: str) -> tuple[tuple[str, Any], ...]:
    f = Fields(node, path, UNET_KEYS)
    if "tcp" not in f:
        raise f.error("give the door's TCP port: tcp (1100 is a UnetStack modem's)")
    return (("tcp", f.get("tcp", integer(1, 65535))), ("host", f.get("host", listen_host, "127.0.0.1")),
            ("protocol", f.get("protocol", integer(0, MAX_PROTOCOL), 0)))
