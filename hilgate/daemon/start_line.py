"""The daemon's start line: what it serves, in words (the links, and the endpoints of the kinds they use)."""

from __future__ import annotations

from typing import Any

__all__ = ["links_phrase", "link_list", "endpoint_list"]


def links_phrase(n: int) -> str:
    return f"{n} link" if n == 1 else f"{n} links"


def link_list(scene: Any, host: str | None, limit: int = 12) -> str:
    parts = [f"{link.id}={link.backend}" for link in scene.links.values() if host is None or link.host == host]
    if len(parts) > limit:
        parts = parts[:limit] + [f"… {len(parts) - limit} more"]
    return ", ".join(parts)


def _emulated(link: Any) -> str | None:
    emulate = dict(link.emulate)
    if not emulate:
        return None
    where = f"pty {emulate['pty']}" if emulate.get("pty") else f"TCP port {emulate.get('tcp')}"
    return f"{link.id} as an emulated {emulate.get('protocol')} modem at {where}"


def _unet(link: Any) -> str | None:
    if not link.unet:
        return None
    door = dict(link.unet)
    return f"{link.id} as a UnetStack node at {door['host']}:{door['tcp']}"


def endpoint_list(scene: Any, host: str | None, runtime_dir: str, tcp: str | None) -> str:
    """The endpoints this daemon opened, for its start line: only the kinds its links use."""
    served = [link for link in scene.links.values() if host is None or link.host == host]
    parts = []
    queues = sum("mq" in link.gli for link in served)
    if queues:
        parts.append(f"POSIX queues /ID_{{tx,rx}}_dlnk_phy ({links_phrase(queues)})")
    sockets = sum("socket" in link.gli for link in served)
    if sockets:
        parts.append(f"sockets {runtime_dir}/gli/ID.sock ({links_phrase(sockets)})")
    if tcp:
        parts.append(f"TCP {tcp}")
    parts.extend(filter(None, map(_unet, served)))
    parts.extend(filter(None, map(_emulated, served)))
    parts.append(f"control {runtime_dir}/control.sock")
    return ", ".join(parts)
