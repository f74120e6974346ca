"""The door table: every way applications (or other hosts) reach a link, declared once, as the driver table
declares the modems.

One :class:`DoorRow` per door says its **name** (for a door a link asks for, the value its ``gli:`` names),
its **title** (as the log names it), how to **open** it (``"module:function"`` of a function given the
daemon's ``DoorSetting``, :mod:`hilgate.daemon.doors`) and whether a link's ``gli:`` asks for it (``gli``)
or every link has it (an emulated modem's, the network's).  The daemon opens every row; the scene loader
reads the ``gli:`` values here: adding a door means its module and a row here.  Installed packages add
rows through the ``hilgate.doors`` entry points (:mod:`hilgate.core.tables`).

Why here, in ``core``, and by name: the scene loader must know the ``gli:`` values, and may not import the
daemon; the doors live in four rooms (``gli``, ``drivers``, ``ros2`` through the bridge, ``daemon``) and
some import what a daemon without such links never needs (Zenoh, DDS).  This module imports none of them.
"""

from __future__ import annotations

from dataclasses import dataclass

from .tables import merge_entry_points

__all__ = ["DoorRow", "DOORS"]


@dataclass(frozen=True)
class DoorRow:
    """One door (see the module's docstring)."""

    name: str
    title: str
    opens: str  # "module:function" (daemon.doors.DoorSetting) -> the door, or None
    gli: bool = False  # a link opens it when its gli: names the row (mq, socket, ros2, unet); else every link


DOORS: dict[str, DoorRow] = {row.name: row for row in (
    DoorRow("mq", "POSIX queues", "hilgate.daemon.doors:open_queues", gli=True),
    DoorRow("socket", "UNIX sockets", "hilgate.daemon.doors:open_sockets", gli=True),
    DoorRow("emulate", "emulated modems", "hilgate.daemon.doors:open_emulated_modems"),
    DoorRow("unet", "UnetStack nodes", "hilgate.daemon.doors:open_unet_nodes", gli=True),
    DoorRow("ros2", "ROS 2", "hilgate.daemon.doors:open_ros2", gli=True),
    DoorRow("zenoh", "the network of hosts", "hilgate.daemon.doors:open_network"),
)}


# last: a plug-in's row module imports this one (its row class, its options), complete by now
merge_entry_points("hilgate.doors", DOORS, lambda row: isinstance(row, DoorRow))  # a lab's own doors
