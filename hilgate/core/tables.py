"""What every table of hilgate shares: rows named by ``"module:attr"``, and rows added by installed packages.

The driver table, the door table, the pose-source table, the MAC registry and the propagation registry
each map a name to a row.  A lab ships its own modem, door, pose source, MAC or propagation model as a
package of its own whose ``pyproject.toml`` declares an entry point in the table's group::

    [project.entry-points."hilgate.drivers"]
    labmodem = "labmodem.row:ROW"

:func:`merge_entry_points` adds such rows to a table when the table's module is imported (so every
process that reads the table sees them: the daemon, the scene loader's worker, ``hilgate check``).  A
plug-in that cannot be loaded, gives something that is not a row, names its row otherwise than its entry
point, or takes a built-in's name stops the start with :class:`PluginRowError`, which names the package:
a scene that silently lost its modem would be worse than a daemon that does not start.

Why by name (``"module:attr"``): a table is read to check scenes, which must not import the drivers,
cameras or DDS that the rows' classes need; :func:`resolve` imports them when the daemon opens one.
"""

from __future__ import annotations

import functools
import importlib
from importlib import metadata
from typing import Any, Callable, MutableMapping

__all__ = ["GROUPS", "PluginRowError", "resolve", "merge_entry_points"]

GROUPS = ("hilgate.drivers", "hilgate.doors", "hilgate.pose_sources", "hilgate.macs", "hilgate.propagation")
"""The entry-point groups a package may add rows through, one per table."""


class PluginRowError(Exception):
    """An installed plug-in's row cannot join its table; the message names the package and the entry point."""


def resolve(reference: str) -> Any:
    """The object ``"module:attr"`` names (its module imported now)."""
    module, _, attr = reference.partition(":")
    return getattr(importlib.import_module(module), attr)  # (by name: the table names it as module:attribute)


@functools.cache
def _installed() -> metadata.EntryPoints:
    """Every installed entry point, read once per process (one walk over the installed packages)."""
    return metadata.entry_points()


def _package(entry: metadata.EntryPoint) -> str:
    dist = getattr(entry, "dist", None)  # (by name: an entry point made by hand has no distribution)
    return f"{dist.name} {dist.version}" if dist is not None else "an unknown package"


def merge_entry_points(group: str, table: MutableMapping[str, Any], is_row: Callable[[Any], bool],
                       name_of: Callable[[Any], str | None] = lambda row: row.name) -> list[str]:
    """Add the rows of ``group``'s entry points to ``table`` (built-in rows are there already); return
    the names added.  ``is_row`` says whether a loaded object is a row of this table; ``name_of`` its
    name (None: the entry point's name is its name)."""
    if group not in GROUPS:
        raise ValueError(f"entry-point group {group!r}: one of {', '.join(GROUPS)}")
    added = []
    for entry in sorted(_installed().select(group=group), key=lambda e: e.name):
        where = f"plug-in {entry.name!r} of {group} (package {_package(entry)}, {entry.value})"
        if entry.name in table:
            raise PluginRowError(f"{where}: {entry.name!r} is a built-in name (or another package's); "
                                 f"rename the entry point and its row")
        try:
            row = entry.load()
        except Exception as exc:
            raise PluginRowError(f"{where} failed to load: {type(exc).__name__}: {exc}") from exc
        if not is_row(row):
            raise PluginRowError(f"{where} is not a row of this table: {type(row).__name__}")
        named = name_of(row)
        if named is not None and named != entry.name:
            raise PluginRowError(f"{where}: its row is named {named!r}; the entry point and the row must have one name")
        table[entry.name] = row
        added.append(entry.name)
    return added
