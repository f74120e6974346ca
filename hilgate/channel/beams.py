"""How many beams BELLHOP's fan needs, found by convergence (``beams: auto``, the default).

BELLHOP's transmission loss depends on the fan: with too few beams each geometric beam is wide, and where
it meets the surface or the bottom part of it is lost, so the loss comes out too high.  A fixed 1 001 beams
over ±80° gave 1 to 4 dB too much loss at 3 to 8 km near the surface in isovelocity water (issue 38).  So
the fan is doubled (1 001, 2 001, 4 001 … beams: each fan holds the one before it and the angles halfway)
until doubling it changes the incoherent transmission loss by at most :data:`TOLERANCE_DB` at 99.9 % of
the grid points (:data:`SHARE`) in the water (not in the sediment under a sloping bottom, nor within the margin of it: below) where
both fans hear something, or until :data:`MOST_BEAMS`, or until the program cannot trace the fan
(pelagic stops at 20 million ray points), where the last fan it traced is kept and a warning says how far
it was from converging.  Points the fan does not reach directly (steeper than ±80° from the source, a
few metres from it in range) are not judged either: more beams do not bring their direct path.

It is judged on a few source depths (the shallowest, the middle and the deepest of the grid): the fan's
needs come from the water's extent and the frequency, and those three bound them.  The receivers nearest
the surface and the bottom are :data:`~hilgate.models.environment.NEAR_BOUNDARY_M` away from them (the
grid's margin): a geometric beam within its own width of a boundary converges as slowly as its width
shrinks (1 m under the surface at 5 km still moved 0.6 dB from 16 001 to 32 001 beams), while the
incoherent field there is the field a little deeper.  Where the bathymetry rises, grid points come as
near the bottom as that, or lie in the sediment, where beams' tails leave values that moved by 45 dB
from one fan to the next in the slope example: those are not judged.  Sans-I/O: the runner passes the
function that runs BELLHOP.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..models.environment import Water
from .envfile import ANGLE_DEG

__all__ = ["TOLERANCE_DB", "SHARE", "FIRST_BEAMS", "MOST_BEAMS", "Choice", "fans", "judged_sources", "judged_points",
           "change_db", "choose_beams"]

log = logging.getLogger(__name__)

TOLERANCE_DB = 0.5
"""A fan has converged when doubling it changes the TL by no more than this at :data:`SHARE` of the grid
points that count."""
SHARE = 0.999
"""The share of the points that must be within the tolerance: the rest (0.04 % in the Munk example) lie
where the field jumps 10 to 20 dB from one grid point to the next (a shadow's edge, a caustic), where a
shift of the edge by a fraction of a cell moves the loss there by dB whatever the fan.  A whole row of
one source depth (a surface's, as in the issue) is 0.2 to 2 % of the points: it is not hidden there."""
FIRST_BEAMS = 1001
MOST_BEAMS = 64001
VERSION = 4
"""Of the rule above: part of the cache's key (a changed rule is new fields)."""


@dataclass(frozen=True)
class Choice:
    """The fan chosen: its beams, the change doubling to it made at :data:`SHARE` of the points (dB; None
    when the first fan was taken as it is) and the largest anywhere, whether it is within the tolerance,
    where the largest was (source depth, receiver depth, range, m), and the TL it gave at each judged
    source depth, [source][depth][range]."""

    beams: int
    change_db: float | None
    converged: bool
    where: tuple[float, float, float] | None
    tl: np.ndarray
    largest_db: float | None = None


def fans() -> list[int]:
    """The fans tried, in order: each holds the one before it and the angles halfway between."""
    out, n = [], FIRST_BEAMS
    while n <= MOST_BEAMS:
        out.append(n)
        n = 2 * n - 1
    return out


def judged_sources(count: int) -> list[int]:
    """The indices of the source depths the fan is judged on: the shallowest, middle and deepest."""
    return sorted({0, count // 2, count - 1})


def judged_points(water: Water, sources: Sequence[float]) -> np.ndarray:
    """Which of an incoherent run's grid points [source][depth][range] count: those in the water at least
    the grid's margin from the surface and from the bottom there, whose direct path from the source
    leaves within the fan (a receiver steeper than :data:`~.envfile.ANGLE_DEG` below or above a source,
    the fan reaches only by reflections and beams' tails: more beams do not make that right)."""
    margin = water.boundary_margin_m - 1e-6
    depths = np.asarray(water.receiver_grid())[None, :, None]
    ranges = np.asarray(water.range_grid())[None, None, :]
    bottom = np.asarray([water.bottom_at(r) for r in water.range_grid()])[None, None, :]
    steep = np.degrees(np.arctan2(np.abs(depths - np.asarray(sources, dtype=float)[:, None, None]), ranges))
    return (depths >= margin) & (depths <= bottom - margin) & (steep <= ANGLE_DEG)


def change_db(before: np.ndarray, after: np.ndarray, cap: float,
              counted: np.ndarray | None = None) -> tuple[float, float, tuple[int, int, int] | None]:
    """|ΔTL| between two fields [source][depth][range] (dB) where both hear something (below ``cap``) at
    the points ``counted``: at :data:`SHARE` of them, the largest, and where that is."""
    both = (before < cap) & (after < cap) & np.isfinite(before) & np.isfinite(after)
    if counted is not None:
        both &= counted
    if not both.any():
        return 0.0, 0.0, None
    diff = np.zeros(np.shape(after))
    diff[both] = np.abs(after[both] - before[both])
    at = np.unravel_index(int(np.argmax(diff)), diff.shape)
    return float(np.quantile(diff[both], SHARE)), float(diff[at]), tuple(int(i) for i in at)


def choose_beams(trace: Callable[[int], np.ndarray], water: Water, sources: Sequence[float], cap: float,
                 failure: type[Exception]) -> Choice:
    """Double the fan from :data:`FIRST_BEAMS` until it converges.  ``trace(beams)`` runs BELLHOP with that
    fan and returns the incoherent TL [source][depth][range] at the judged ``sources`` on ``water``'s grid
    (raising ``failure`` when the program cannot); a failure on any fan after the first keeps the one
    before."""
    depths, ranges, counted = water.receiver_grid(), water.range_grid(), judged_points(water, sources)
    tried = fans()
    previous = trace(tried[0])
    last = Choice(tried[0], None, False, None, previous)
    for beams in tried[1:]:
        try:
            tl = trace(beams)
        except failure as exc:
            log.warning("BELLHOP could not trace %d beams (%s): keeping %d, whose TL moved by %s from the fan "
                        "before it at %g %% of the grid (not converged within %g dB)", beams, str(exc)[-200:],
                        last.beams, "?" if last.change_db is None else f"{last.change_db:.2f} dB", 100 * SHARE,
                        TOLERANCE_DB)
            return last
        change, largest, at = change_db(previous, tl, cap, counted)
        where = None if at is None else (float(sources[at[0]]), float(depths[at[1]]), float(ranges[at[2]]))
        last = Choice(beams, change, change <= TOLERANCE_DB, where, tl, largest)
        log.info("BELLHOP's fan of %d beams moved the TL by %.2f dB at %g %% of the grid, %.2f dB at most%s", beams,
                 change, 100 * SHARE, largest, _at(where))
        if last.converged:
            return last
        previous = tl
    log.warning("BELLHOP's fan did not converge within %d beams: doubling it to %d changed the TL by %.2f dB at "
                "%g %% of the grid; keeping %d (give water: beams: N to choose yourself)", MOST_BEAMS, last.beams,
                last.change_db, 100 * SHARE, last.beams)
    return last


def _at(where: tuple[float, float, float] | None) -> str:
    return "" if where is None else " (at source %g m, receiver %g m, %g m)" % where
