"""A scene spread over hosts: which daemon serves each link, vehicle and camera, and the ``zenoh:``
section that joins the daemons into one network.

The same scene file runs on every host; each daemon is started with its host name (``--host``) and
serves only what names it.  ``host:`` may be left out where there is nothing to choose:

- a link without ``host:`` belongs to the only host the scene names (or, in a scene that names
  none, to the one daemon that runs it);
- a vehicle's pose is computed or measured on its ``host:``, by default the host of its first link
  (the host that owns it publishes it to the others);
- a camera runs on the host of the vehicles it tracks (``onboard``: of its vehicle).

Host names go into Zenoh key expressions, so they are letters, digits, ``_``, ``.`` and ``-``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

from ..core.names import zenoh_prefix_problem
from .checks import Fields, boolean, matching, number, one_or_more, path_value, text
from .yaml_nodes import Node

__all__ = ["ZenohSpec", "HOST_NAME", "host_name", "zenoh_spec", "resolve_hosts"]

HOST_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")
ENDPOINT = re.compile(r"(tcp|udp|tls|quic|unixsock-stream|ws)/[^\s]{1,200}")
ZENOH_KEYS = ("connect", "listen", "multicast_scouting", "prefix", "lease_s", "pose_rate_hz", "config", "credentials",
              "insecure")
LOOPBACK = ("tcp/127.0.0.1:0",)


@dataclass(frozen=True)
class ZenohSpec:
    """How this daemon joins the others (docs/several-hosts.md).  ``listen`` is loopback unless the
    scene or ``--zenoh-listen`` says otherwise; multicast scouting is off unless asked, so a daemon
    never announces itself on a vehicle's network by surprise."""

    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = LOOPBACK
    multicast_scouting: bool = False
    prefix: str = "hilgate"
    lease_s: float = 1.0
    pose_rate_hz: float = 10.0
    config: str | None = None  # a Zenoh JSON5 configuration file, read first
    credentials: str | None = None  # the lab's credentials (hilgate network init): TLS and access control
    insecure: bool = False  # no credentials, asked for in so many words: plain TCP, anyone may say anything


host_name = matching(HOST_NAME, "a host name is letters, digits, '_', '.' or '-' (at most 64)")
_endpoints = one_or_more(matching(ENDPOINT, "a Zenoh endpoint is like tcp/192.168.1.10:7447"))


def _prefix(node: Node, path: str) -> str:
    value = text(node, path)
    problem = zenoh_prefix_problem(value)
    if problem:
        raise node.error(path, problem)
    return value


def zenoh_spec(node: Node) -> ZenohSpec:
    f = Fields(node, "zenoh", ZENOH_KEYS)
    if "credentials" in f and f.get("insecure", boolean, False):
        raise node.error("zenoh.insecure", "give either credentials (TLS and access control) or insecure: true, not both")
    return ZenohSpec(
        connect=f.get("connect", _endpoints, ()),
        listen=f.get("listen", _endpoints, LOOPBACK) or LOOPBACK,
        multicast_scouting=f.get("multicast_scouting", boolean, False),
        prefix=f.get("prefix", _prefix, "hilgate"),
        lease_s=f.get("lease_s", number(0.1, 60), 1.0),
        pose_rate_hz=f.get("pose_rate_hz", number(above=0, maximum=1000), 10.0),
        config=f.get("config", path_value, None),
        credentials=f.get("credentials", path_value, None),
        insecure=f.get("insecure", boolean, False),
    )


def resolve_hosts(links: dict[str, Any], vehicles: dict[str, Any], cameras: dict[str, Any],
                  link_nodes: dict[str, Node], root: Node) -> tuple[tuple[str, ...], dict, dict, dict]:
    """Fill in every left-out ``host:`` (the rules in the module's docstring); returns the hosts the
    scene names, in order of appearance, and the specs with their hosts."""
    named: list[str] = []
    for spec in (*links.values(), *vehicles.values(), *cameras.values()):
        if spec.host is not None and spec.host not in named:
            named.append(spec.host)
    if not named:
        return (), links, vehicles, cameras
    resolved_links = {}
    for link_id, spec in links.items():
        if spec.host is None:
            if len(named) > 1:
                raise link_nodes[link_id].error(
                    f"links.{link_id}", f"missing 'host': the scene names several hosts ({', '.join(named)}); "
                                        "say which one serves this link")
            spec = replace(spec, host=named[0])
        resolved_links[link_id] = spec
    resolved_vehicles = {}
    for name, spec in vehicles.items():
        if spec.host is None:
            first = next((link.host for link in resolved_links.values() if link.vehicle == name), named[0])
            spec = replace(spec, host=first)
        resolved_vehicles[name] = spec
    resolved_cameras = {}
    for name, camera in cameras.items():
        tracked = _tracked_vehicles(name, camera, resolved_vehicles)
        hosts = {resolved_vehicles[v].host for v in tracked}
        host = camera.host or (next(iter(hosts)) if len(hosts) == 1 else named[0])
        if hosts - {host}:
            raise root.error(f"cameras.{name}.host", f"a camera runs on the host of the vehicles it tracks; "
                                                     f"{name!r} is on {host!r}, its vehicles on {', '.join(sorted(hosts))}")
        resolved_cameras[name] = replace(camera, host=host)
    return tuple(named), resolved_links, resolved_vehicles, resolved_cameras


def _tracked_vehicles(name: str, camera: Any, vehicles: dict[str, Any]) -> list[str]:
    if camera.onboard is not None:
        return [camera.onboard[0]]
    tracked = []
    for vname, vehicle in vehicles.items():
        if vehicle.pose.kind == "live":
            for kind, params in vehicle.pose.params:
                if kind == "aruco" and dict(params).get("camera") == name:
                    tracked.append(vname)
    return tracked

