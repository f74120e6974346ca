"""Delay and loss of one path, from one place: the propagation model a channel asks (ns-3's ``PropModel``).

Every (sender, receiver) pair gets its delay and its loss model here, static or moving alike: the medium
asks :meth:`Propagation.delay` once for a static pair and at every transmission for a moving one, and
:meth:`Propagation.bind` once per pair for the loss model it hands with each arrival.  Nothing else in
the models computes a path delay (``Medium.propagation_delay`` for an emulated modem, ``SimModem.tau_at``
for a MAC's timing ask the same object), so a channel that replaces it, such as a ray-traced (BELLHOP)
channel, changes every path at once.

:class:`StraightLine` is the model of a channel without water: sound on a straight line at one speed,
the loss of the receiver's error model bound to the sender (``path.py``).  A channel with ``water:`` has
:class:`~.bellhop_fields.BellhopChannel` instead, once its fields are ready: BELLHOP's delay and
transmission loss at both ends' positions, looked up per arrival (``positional``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from .path import BoundPath, PathEnd, bind_path

if TYPE_CHECKING:
    from .trajectories import Vec3

__all__ = ["Propagation", "StraightLine"]


class Propagation(Protocol):
    """What a channel is asked for every path."""

    positional: bool
    """False: the loss model :meth:`bind` gives is one of distance (``per(d, size)``) and :meth:`delay`
    gives every arrival's delay.  True (a ray-traced channel): the bound model's ``at(a, b)`` is one
    arrival's loss model at both ends' positions, with its ``delay`` (the channel's ``min_delay_s`` is
    added to it by the medium); the medium asks it once for a static pair, at every arrival for a moving
    one."""

    distance_only: bool
    """True: :meth:`delay` and the bound loss model depend on the distance alone, never on where the ends
    are, and the delay grows with the distance.  The medium may then count a dense scene's static pairs
    that judge nothing instead of listing them (``air.py``'s quiet pairs work their delay out from the
    distance); a model that is not (a ray-traced channel) has every pair listed."""

    def delay(self, d: float, a: "Vec3 | None" = None, b: "Vec3 | None" = None) -> float:
        """Seconds from the sender at ``a`` to the receiver at ``b``, ``d`` metres apart.  Without
        positions (a MAC's timing at its range: ``SimModem.tau_at``) a model that needs them answers
        for the distance alone."""

    def bind(self, sender: PathEnd, receiver: PathEnd) -> BoundPath:
        """The loss model of frames from ``sender`` at ``receiver`` (asked once per pair), and whether
        the receiver refuses them (``path.BoundPath``)."""


@dataclass(frozen=True)
class StraightLine:
    """τ = ``min_delay_s`` + d / ``speed_mps``; the loss of the receiver's error model (``bind_path``)."""

    speed_mps: float
    min_delay_s: float = 0.0
    positional = False
    distance_only = True

    def delay(self, d: float, a: "Vec3 | None" = None, b: "Vec3 | None" = None) -> float:
        return self.min_delay_s + d / self.speed_mps

    def bind(self, sender: PathEnd, receiver: PathEnd) -> BoundPath:
        return bind_path(sender, receiver)
