"""What a receiving modem measures about a frame it heard: distance, radial speed, RSSI and integrity.

An EvoLogics modem prints these with every reception (``RECVIM``'s rssi, integrity and velocity
fields, ``AT?E``/``?I``/``?V``, the USBL fixes).  Drivers log them and navigation filters use them, so
constants (the emulator's old 150 / 0.00) hide what a bench test should exercise.

The numbers come from a deliberately simple, documented model, one part with a small interface
(:class:`LinkBudget`) so that a physical channel model (noise, spreading, absorption by frequency;
being built on its own branch) replaces it without touching the callers:

- **RSSI** (dB re 1 V, negative): ``RSSI_AT_1M_DB − 20·log10(max(d, 1 m)) − ABSORPTION_DB_PER_KM·d/1000``:
  spherical spreading plus a flat absorption of about 1 dB/km (Thorp's figure near 10 kHz).
- **Integrity** (the modem's decoding quality, > 100 means good): falls linearly from
  ``INTEGRITY_NEAR`` at 0 m to ``INTEGRITY_FAR`` at the sender's maximum range (constant
  ``INTEGRITY_NEAR`` when the range is unlimited).
- **Velocity** (m/s): the rate at which the distance between the two vehicles shrinks (positive
  when they approach, as a Doppler shift is), from their poses: a forward difference over
  :data:`VELOCITY_STEP_S`, exact within a straight leg of a path; live vehicles give it through the
  velocity they report.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from .trajectories import PoseSource, Vec3

RSSI_AT_1M_DB = -20.0
ABSORPTION_DB_PER_KM = 1.0
INTEGRITY_NEAR = 250
INTEGRITY_FAR = 50
VELOCITY_STEP_S = 0.01


class LinkBudget(Protocol):
    """What a reception's quality figures come from: the seam for a physical channel model."""

    def rssi_db(self, d: float) -> float: ...

    def integrity(self, d: float) -> int: ...


class SimpleLinkBudget:
    """The model of the module doc, for a sender whose range ends at ``max_range_m``."""

    def __init__(self, max_range_m: float = math.inf):
        self.max_range_m = max_range_m

    def rssi_db(self, d: float) -> float:
        return RSSI_AT_1M_DB - 20.0 * math.log10(max(d, 1.0)) - ABSORPTION_DB_PER_KM * d / 1000.0

    def integrity(self, d: float) -> int:
        if not math.isfinite(self.max_range_m) or self.max_range_m <= 0.0:
            return INTEGRITY_NEAR
        share = min(1.0, max(0.0, d / self.max_range_m))
        return round(INTEGRITY_NEAR - (INTEGRITY_NEAR - INTEGRITY_FAR) * share)


@dataclass(frozen=True)
class Reception:
    """A reception as the receiving modem measures it, at model time ``t``."""

    t: float
    receiver: "Vec3"  # where the receiving modem is (the scene's frame: x north, y east, z down)
    sender: "Vec3"
    distance_m: float
    velocity_mps: float  # positive when approaching
    rssi_db: int
    integrity: int


def radial_speed(sender: "PoseSource", receiver: "PoseSource", t: float, step: float = VELOCITY_STEP_S) -> float:
    """How fast the distance between the two shrinks at ``t`` (m/s, positive when approaching)."""
    a0, b0 = sender.position(t), receiver.position(t)
    a1, b1 = sender.position(t + step), receiver.position(t + step)
    if a0 is None or b0 is None or a1 is None or b1 is None:
        return 0.0
    return (math.dist(a0, b0) - math.dist(a1, b1)) / step


def reception(sender: "PoseSource", receiver: "PoseSource", t: float, budget: LinkBudget) -> Reception | None:
    """What the receiver measures of a frame from ``sender`` heard at ``t`` (None without both poses)."""
    a, b = sender.position(t), receiver.position(t)
    if a is None or b is None:
        return None
    d = math.dist(a, b)
    return Reception(t, tuple(b), tuple(a), d, radial_speed(sender, receiver, t), round(budget.rssi_db(d)),
                     budget.integrity(d))
