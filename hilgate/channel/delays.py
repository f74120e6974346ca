"""The delay a frame takes, reduced from BELLHOP's arrivals so that a lookup between grid points follows
one arrival.

At each grid point the delay is the first arrival within ``threshold_db`` of the strongest there (the
*anchor*).  Which path that is jumps between neighbouring points (the direct path at one, a surface
echo 5 ms later at the next, as a path's amplitude crosses the threshold), so interpolating the anchors'
delays gave, between the points, delays no path has.  Instead each point keeps its anchor's delay and
the slope of that same arrival along range, receiver depth and source depth: the lookup takes the
nearest point's anchor and follows it to the query along those slopes (``models/bellhop_fields.py``).

The same arrival at a neighbouring point is the one with the same surface and bottom bounces, launched
and received in the same directions (up or down), whose residual delay is nearest the anchor's: an
eigenray's residual changes little from one point to the next, and BELLHOP lists a grazing eigenray as a
cluster of neighbouring beams (delays within a millisecond, launch angles shifting with the source's
depth), so the nearest launch angle picked a cluster's faint edge, 1 to 2 ms off.  A slope is taken
across both neighbours where the arrival is found at both, from one side where at one, and is zero where
at neither.  What is followed is the residual, delay − R/c̄ (R the slant distance, c̄ the mean sound
speed), as the lookup adds R/c̄ back.  Sans-I/O: arrays in, arrays out; a source depth's arrivals at a
time, with its neighbours'.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .arrfile import ArrivalFile, first_and_spread

__all__ = ["Anchors", "anchors_of", "follow", "slopes", "DelayReduction"]


def _key(arrivals: ArrivalFile) -> np.ndarray:
    """Each arrival's kind of path: its bounces and the directions it leaves and arrives in."""
    up = np.sign(arrivals.source_angle_deg).astype(np.int64) + 1
    down = np.sign(arrivals.receiver_angle_deg).astype(np.int64) + 1
    return ((arrivals.surface_bounces * 1000 + arrivals.bottom_bounces) * 3 + up) * 3 + down


@dataclass(frozen=True)
class Anchors:
    """One source depth's first arrivals, per receiver (depth-major, as the file lists them): the kind
    of path (-1 where nothing arrives) and its delay (NaN where nothing arrives)."""

    key: np.ndarray
    delay: np.ndarray


def anchors_of(arrivals: ArrivalFile, threshold_db: float) -> Anchors:
    """The first arrival within ``threshold_db`` of the strongest at each receiver of a file's first
    source depth (the runner asks BELLHOP for one source depth at a time)."""
    nrz, nrr = arrivals.shape[1], arrivals.shape[2]
    n = nrz * nrr
    offsets = arrivals.offsets[:n + 1]
    counts = np.diff(offsets)
    owner = np.repeat(np.arange(n), counts)
    rows = np.arange(offsets[-1])
    amp = np.abs(arrivals.amplitude[:offsets[-1]])
    delay = arrivals.delay_s[:offsets[-1]]
    strongest = np.zeros(n)
    np.maximum.at(strongest, owner, amp)
    keep = (amp >= strongest[owner] * 10.0 ** (-threshold_db / 20.0)) & (amp > 0.0)
    first = np.full(n, np.inf)
    np.minimum.at(first, owner[keep], delay[keep])
    # the row that is the first: the earliest kept one (of equal delays, the first listed)
    chosen = np.full(n, len(rows), dtype=np.int64)
    hit = keep & (delay == first[owner])
    np.minimum.at(chosen, owner[hit], rows[hit])
    chosen[chosen == len(rows)] = -1
    key = np.full(n, -1, dtype=np.int64)
    found = chosen >= 0
    key[found] = _key(arrivals)[chosen[found]]
    out = np.full(n, np.nan)
    out[found] = delay[chosen[found]]
    return Anchors(key, out)


def follow(anchors: Anchors, arrivals: ArrivalFile, shift: tuple[int, int], expected: np.ndarray) -> np.ndarray:
    """The delay, at the receiver ``shift`` = (depths, ranges) away in ``arrivals`` (the same source depth's
    file or a neighbouring one's, on the same receivers), of the arrival each anchor is: the same kind of
    path whose delay is nearest ``expected`` (the anchor's delay moved by the straight line's change, i.e.
    the same residual).  NaN where the neighbour is off the grid or has no such path."""
    nrz, nrr = arrivals.shape[1], arrivals.shape[2]
    n = nrz * nrr
    dz, dr = shift
    iz, ir = np.divmod(np.arange(n), nrr)
    tz, tr = iz + dz, ir + dr
    target = np.where((tz >= 0) & (tz < nrz) & (tr >= 0) & (tr < nrr) & (anchors.key >= 0), tz * nrr + tr, -1)
    offsets = arrivals.offsets[:n + 1]
    owner = np.repeat(np.arange(n), np.diff(offsets))
    # rows sorted by (receiver, kind of path): each anchor's candidates are one contiguous run
    span = np.int64(1) << 40
    composite = owner.astype(np.int64) * span + _key(arrivals)[:offsets[-1]]
    order = np.argsort(composite, kind="stable")
    composite = composite[order]
    wanted = np.where(target >= 0, target * span + np.maximum(anchors.key, 0), -1)
    lo = np.searchsorted(composite, wanted, "left")
    hi = np.searchsorted(composite, wanted, "right")
    hi[target < 0] = lo[target < 0]
    best = np.full(n, np.inf)
    out = np.full(n, np.nan)
    delays = arrivals.delay_s[order]
    for j in range(int((hi - lo).max(initial=0))):
        at = lo + j
        there = at < hi
        pick = np.flatnonzero(there)
        gap = np.abs(delays[at[pick]] - expected[pick])
        better = gap < best[pick]
        pick = pick[better]
        best[pick] = gap[better]
        out[pick] = delays[at[pick]]
    return out


def slopes(residual: np.ndarray, before: np.ndarray, after: np.ndarray, step: float) -> np.ndarray:
    """The slope of each point's arrival from its residual delay at the neighbour before and after it (NaN
    where not found there): across both where found at both, else from the one side, else zero."""
    both = np.isfinite(before) & np.isfinite(after)
    only_after = np.isfinite(after) & ~both
    only_before = np.isfinite(before) & ~both
    out = np.zeros_like(residual)
    out[both] = (after[both] - before[both]) / (2.0 * step)
    out[only_after] = (after[only_after] - residual[only_after]) / step
    out[only_before] = (residual[only_before] - before[only_before]) / step
    out[~np.isfinite(residual)] = 0.0
    return out


class DelayReduction:
    """The delay grids of one frequency, from its arrivals files given one source depth at a time, in
    order (:meth:`add`); only the last one is kept between calls (a file is tens of megabytes).

    :meth:`result`: ``first`` (the anchor's delay, the straight line's where nothing arrives),
    ``first_dz``, ``first_dr``, ``first_ds`` (its residual's slope along receiver depth, range and
    source depth, s/m) and ``spread`` (the RMS delay spread of the arrivals within the threshold, 0
    where nothing arrives), each [source][depth][range]."""

    def __init__(self, sources: list[float], threshold_db: float, mean_speed_mps: float):
        self.sources = [float(z) for z in sources]
        self.threshold_db = threshold_db
        self.speed = mean_speed_mps
        self.planes: list[dict[str, np.ndarray]] = []
        self._last: tuple[ArrivalFile, Anchors] | None = None
        self.depths = self.ranges = np.zeros(0)

    def _straight(self, zs: float, shift: tuple[int, int]) -> np.ndarray:
        """The straight line's delay from ``zs`` to each point shifted by ``shift`` (clamped to the grid)."""
        nz, nr = len(self.depths), len(self.ranges)
        iz, ir = np.divmod(np.arange(nz * nr), nr)
        tz = np.clip(iz + shift[0], 0, nz - 1)
        tr = np.clip(ir + shift[1], 0, nr - 1)
        return np.hypot(self.ranges[tr], self.depths[tz] - zs) / self.speed

    def _neighbour(self, anchors: Anchors, residual: np.ndarray, arrivals: ArrivalFile, zs: float,
                   shift: tuple[int, int]) -> np.ndarray:
        """The residual delay of each anchor's arrival at its neighbour ``shift`` away in ``arrivals`` (whose
        source is at ``zs``)."""
        straight = self._straight(zs, shift)
        return follow(anchors, arrivals, shift, residual + straight) - straight

    def add(self, arrivals: ArrivalFile) -> None:
        n = len(self.planes)
        zs = self.sources[n]
        self.depths, self.ranges = arrivals.receiver_depths, arrivals.ranges
        anchors = anchors_of(arrivals, self.threshold_db)
        residual = anchors.delay - self._straight(zs, (0, 0))
        plane = {"residual": residual, "delay": anchors.delay,
                 "spread": first_and_spread(arrivals, self.threshold_db)[1][0].ravel()}
        for name, shift in (("up", (-1, 0)), ("down", (1, 0)), ("near", (0, -1)), ("far", (0, 1))):
            plane[name] = self._neighbour(anchors, residual, arrivals, zs, shift)
        plane["shallower"] = plane["deeper"] = np.full(len(anchors.delay), np.nan)
        if self._last is not None:
            last_arrivals, last_anchors = self._last
            last = self.planes[-1]
            last["deeper"] = self._neighbour(last_anchors, last["residual"], arrivals, zs, (0, 0))
            plane["shallower"] = self._neighbour(anchors, residual, last_arrivals, self.sources[n - 1], (0, 0))
        self.planes.append(plane)
        self._last = (arrivals, anchors)

    def result(self) -> dict[str, np.ndarray]:
        self._last = None
        shape = (len(self.planes), len(self.depths), len(self.ranges))
        dz = self.depths[1] - self.depths[0] if len(self.depths) > 1 else 1.0
        dr = self.ranges[1] - self.ranges[0] if len(self.ranges) > 1 else 1.0
        ds = self.sources[1] - self.sources[0] if len(self.sources) > 1 else 1.0
        zs = np.asarray(self.sources)[:, None, None]
        straight = np.hypot(self.ranges[None, None, :], self.depths[None, :, None] - zs) / self.speed
        out = {}
        delay = np.stack([p["delay"] for p in self.planes]).reshape(shape)
        out["first"] = np.where(np.isfinite(delay), delay, straight)
        for name, before, after, step in (("first_dz", "up", "down", dz), ("first_dr", "near", "far", dr),
                                          ("first_ds", "shallower", "deeper", ds)):
            out[name] = np.stack([slopes(p["residual"], p[before], p[after], step) for p in self.planes]).reshape(shape)
        spread = np.stack([p["spread"] for p in self.planes]).reshape(shape)
        out["spread"] = np.where(np.isfinite(spread), spread, 0.0)
        return out
