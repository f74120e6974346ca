"""Modems inside their channel's water: a scripted vehicle whose modem is on a channel with ``water:``
must stay between the sea surface and the bottom, or the lookup would silently clamp it into the water
(a sender under the bottom took the field of the deepest source bin; one above the surface, the
shallowest).  Each place a scene gives is checked where it is written (``FILE:LINE:
vehicles.NAME.pose.…[2]: …``): a static pose, a path's start and every leg's end, every waypoint, a
controlled vehicle's start.  Between them a vehicle moves in straight lines, which stay in the water
when their ends do.  Live poses (MAVLink, ArUco, ROS 2) are not known before they come.

The bottom is the one under a sender (``depth_m``: the bathymetry is depth against range from the
sender) for a modem that sends on the channel, and the deepest water for one that only listens there.
"""

from __future__ import annotations

from typing import Iterator, Mapping

from ..models.medium import Channel
from .checks import join_path
from .specs import LinkSpec
from .yaml_nodes import Node

__all__ = ["check_modems_in_water"]


def _places(pose: Node, path: str) -> Iterator[tuple[Node, str]]:
    """Each z a scripted pose gives (its node and key); a live or malformed pose gives none (the vehicle's
    own checks have passed by now)."""
    if not pose.is_map:
        return
    for kind, params in pose.items():
        where = join_path(path, kind)
        if kind == "static":
            yield from _z(params, where, 2)
        elif kind in ("path", "controlled") and params.is_map:
            start = params.value.get("start")
            if start is not None:
                yield from _z(start, join_path(where, "start"), 2)
            legs = params.value.get("legs") if kind == "path" else None
            for i, leg in enumerate(legs.value if legs is not None and legs.is_list else []):
                to = leg.value.get("to") if leg.is_map else None
                if to is not None:
                    yield from _z(to, join_path(join_path(join_path(where, "legs"), i), "to"), 2)
        elif kind == "waypoints" and params.is_list:
            for i, row in enumerate(params.value):
                yield from _z(row, join_path(where, i), 3)


def _z(node: Node, path: str, index: int) -> Iterator[tuple[Node, str]]:
    if node.is_list and len(node.value) > index:
        yield node.value[index], join_path(path, index)


def check_modems_in_water(channels: Mapping[str, Channel], vehicles: Node, links: Mapping[str, LinkSpec]) -> None:
    """Raise the scene's error for the first place of a vehicle, with a modem on a channel with water,
    that is above that water's surface or below its bottom."""
    for name, channel in channels.items():
        water = channel.water
        if water is None:
            continue
        for link in links.values():
            sends = link.params.tx_channel == name
            if not sends and link.params.rx_channel != name:
                continue
            bottom = water.depth_m if sends else water.deepest_m
            vehicle = vehicles.value.get(link.vehicle)
            pose = vehicle.value.get("pose") if vehicle is not None and vehicle.is_map else None
            if pose is None:
                continue
            role = "sends" if sends else "listens"
            for node, path in _places(pose, join_path(join_path("vehicles", link.vehicle), "pose")):
                z = float(node.value)
                depth = z - water.surface_z_m
                surface = f"z {z:g}, the surface at z {water.surface_z_m:g}"
                if depth < 0.0:
                    raise node.error(path, f"{-depth:g} m above the surface ({surface}) of channel {name}'s water, "
                                           f"where link {link.id} {role}: a modem must be in the water")
                if depth > bottom:
                    under = "under a sender" if sends else "at its deepest"
                    raise node.error(path, f"{depth:g} m deep ({surface}): below the bottom of channel {name}'s "
                                           f"water ({bottom:g} m {under}), where link {link.id} {role}")
