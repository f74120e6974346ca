"""The propagation models a channel's ``propagation:`` can name, as ``mac:`` names a MAC (``macs.py``).

A :class:`PropagationModel` row says the model's **name**, its **title**, how to **make** a channel's
propagation (``make(channel)``: a :class:`~.propagation.Propagation` from the channel's ``speed_mps``,
``min_delay_s`` and ``water``), whether it takes the channel's ``water:`` (required then, refused
otherwise), and whether it is **traced**: computed before the run from the water (BELLHOP's fields,
``hilgate channel prepare``), until when the channel's paths are the straight line's.

A channel without ``propagation:`` keeps what a scene always had: the straight line, or BELLHOP when it
gives ``water:`` (:func:`implied`).  Installed packages add rows through the ``hilgate.propagation``
entry points, merged by the scene loader (``hilgate.scene.channels``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from .propagation import Propagation, StraightLine

__all__ = ["PropagationModel", "PROPAGATIONS", "implied"]


@dataclass(frozen=True)
class PropagationModel:
    """One model a channel can name (see the module's docstring)."""

    name: str
    title: str
    make: Callable[[Any], Propagation]  # (the channel) -> its propagation
    water: bool = False   # takes the channel's water: (then it must be given)
    traced: bool = False  # its fields are computed from the water before the run (BELLHOP)


def _straight_line(channel: Any) -> Propagation:
    return StraightLine(channel.speed_mps, channel.min_delay_s)


PROPAGATIONS: dict[str, PropagationModel] = {row.name: row for row in (
    PropagationModel("straight-line", "sound on a straight line at the channel's speed", _straight_line),
    PropagationModel("bellhop", "BELLHOP's rays through the channel's water", _straight_line, water=True,
                     traced=True),
)}


def implied(water: Any) -> str:
    """The model of a channel that names none: BELLHOP through its water, else the straight line."""
    return "straight-line" if water is None else "bellhop"
