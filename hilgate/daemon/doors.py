"""The doors the daemon opens: each row of the door table (:mod:`hilgate.core.door_table`) names a function of
here (or of a package's) given the daemon's :class:`DoorSetting`, which returns the door (a
``core.endpoint.Door``: it opens each link's endpoints of its kind), or None when this daemon needs none (a
daemon of one host has no network door).  The daemon opens every row, in the table's order (the order a new
link's endpoints open in), and gives the doors to the router.

A door that is more than a door (the ROS 2 bridge also reads poses; the network also claims the scene's
links and follows reloads) leaves the object the daemon talks to in :attr:`DoorSetting.parts` under its
row's name."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from ..core.door_table import DOORS
from ..core.tables import resolve

__all__ = ["DoorSetting", "open_doors"]


@dataclass
class DoorSetting:
    """What a door is opened with: the daemon's loop, router, recorder and options, the scene it starts
    with, this daemon's host in a scene of several (None: one daemon), its GLI client bounds and the
    group its files belong to; ``parts``: what doors leave for the daemon, by row name."""

    scheduler: Any
    router: Any
    recorder: Any
    options: Any  # daemon.options.DaemonOptions
    scene: Any
    host: str | None
    clients: Any  # gli.sockets.ClientLimits
    group: int | None
    parts: dict[str, Any] = field(default_factory=dict)

    def served(self) -> list[Any]:
        """The scene's links this daemon serves."""
        return [link for link in self.scene.links.values() if self.host in (None, link.host)]


def open_queues(setting: DoorSetting) -> Any:
    from ..gli.queues import QueueDoor, plan_message_size

    full = plan_message_size(sum(1 for link in setting.served() if "mq" in link.gli))
    return QueueDoor(setting.scheduler, full, setting.options.gli_backlog, setting.group)


def open_sockets(setting: DoorSetting) -> Any:
    from ..gli.sockets import SocketDoor

    return SocketDoor(os.path.join(setting.options.runtime_dir, "gli"), setting.scheduler, setting.clients,
                      setting.router.port, setting.group)


def open_emulated_modems(setting: DoorSetting) -> Any:
    from ..drivers.emulators import EmulatorDoor

    return EmulatorDoor(setting.scheduler)


def open_unet_nodes(setting: DoorSetting) -> Any:
    from ..gli.unet_door import UnetDoor

    return UnetDoor(setting.scheduler)


def open_ros2(setting: DoorSetting) -> Any:
    """Opens nothing, and loads no DDS, for links not on ROS 2."""
    from .ros2_bridge import Ros2Bridge

    bridge = setting.parts["ros2"] = Ros2Bridge(setting.scheduler, setting.router, setting.options.scene_path)
    return bridge


def open_network(setting: DoorSetting) -> Any:
    """Zenoh between the hosts of a scene spread over several (none for a daemon of one host)."""
    if setting.host is None:
        return None
    from .network_setup import join

    setting.parts["network"], door = join(setting)
    return door


def open_doors(setting: DoorSetting) -> list[Any]:
    """Every row's door for this daemon, in the table's order (the rows that open none left out); a row
    that raises stops the start (the daemon closes what was opened)."""
    doors = []
    for row in DOORS.values():
        door = resolve(row.opens)(setting)
        if door is not None:
            doors.append(door)
    return doors
