"""The door table: every way applications (or other hosts) reach a link, declared once, as the driver table
declares the modems.

One :class:`DoorRow` per door says its **name**, its **title** (as the log names it) and how to **open** it:
``"module:function"`` of a function given the daemon's :class:`DoorSetting` that returns the door (a
``core.endpoint.Door``: it opens each link's endpoints of its kind), or None when this daemon needs none
(a daemon of one host has no network door).  The daemon opens every row, in the table's order (the order
a new link's endpoints open in), and gives the doors to the router: adding a door means its module and a
row here.  Installed packages add rows through the ``hilgate.doors`` entry points (:mod:`hilgate.core.tables`).

A door that is more than a door (the ROS 2 bridge also reads poses; the network also claims the scene's
links and follows reloads) leaves the object the daemon talks to in :attr:`DoorSetting.parts` under its
row's name.

Why by name: the doors live in four rooms (``gli``, ``drivers``, ``ros2`` through the bridge, ``daemon``)
and some import what a daemon without such links never needs (Zenoh, DDS); the table imports none of them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from ..core.tables import merge_entry_points, resolve

__all__ = ["DoorRow", "DoorSetting", "DOORS", "open_doors"]


@dataclass(frozen=True)
class DoorRow:
    """One door (see the module's docstring)."""

    name: str
    title: str
    opens: str  # "module:function" (DoorSetting) -> the door, or None


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


def _queues(setting: DoorSetting) -> Any:
    from ..gli.queues import QueueDoor, plan_message_size

    full = plan_message_size(sum(1 for link in setting.served() if "mq" in link.gli))
    return QueueDoor(setting.scheduler, full, setting.options.gli_backlog, setting.group)


def _sockets(setting: DoorSetting) -> Any:
    from ..gli.sockets import SocketDoor

    return SocketDoor(os.path.join(setting.options.runtime_dir, "gli"), setting.scheduler, setting.clients,
                      setting.router.port, setting.group)


def _emulated_modems(setting: DoorSetting) -> Any:
    from ..drivers.emulators import EmulatorDoor

    return EmulatorDoor(setting.scheduler)


def _unet_nodes(setting: DoorSetting) -> Any:
    from ..gli.unet_door import UnetDoor

    return UnetDoor(setting.scheduler)


def _ros2(setting: DoorSetting) -> Any:
    """Opens nothing, and loads no DDS, for links not on ROS 2."""
    from .ros2_bridge import Ros2Bridge

    bridge = setting.parts["ros2"] = Ros2Bridge(setting.scheduler, setting.router, setting.options.scene_path)
    return bridge


def _network(setting: DoorSetting) -> Any:
    """Zenoh between the hosts of a scene spread over several (none for a daemon of one host)."""
    if setting.host is None:
        return None
    from .network_setup import join

    setting.parts["network"], door = join(setting)
    return door


DOORS: dict[str, DoorRow] = {row.name: row for row in (
    DoorRow("mq", "POSIX queues", "hilgate.daemon.doors:_queues"),
    DoorRow("socket", "UNIX sockets", "hilgate.daemon.doors:_sockets"),
    DoorRow("emulate", "emulated modems", "hilgate.daemon.doors:_emulated_modems"),
    DoorRow("unet", "UnetStack nodes", "hilgate.daemon.doors:_unet_nodes"),
    DoorRow("ros2", "ROS 2", "hilgate.daemon.doors:_ros2"),
    DoorRow("zenoh", "the network of hosts", "hilgate.daemon.doors:_network"),
)}


def open_doors(setting: DoorSetting) -> list[Any]:
    """Every row's door for this daemon, in the table's order (the rows that open none left out); a row
    that raises stops the start (the daemon closes what was opened)."""
    doors = []
    for row in DOORS.values():
        door = resolve(row.opens)(setting)
        if door is not None:
            doors.append(door)
    return doors


# last: a plug-in's row module imports this one (its row class, its options), complete by now
merge_entry_points("hilgate.doors", DOORS, lambda row: isinstance(row, DoorRow))  # a lab's own doors
