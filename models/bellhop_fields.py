"""A channel that knows the water: BELLHOP's fields, computed once, looked up per arrival in O(1).

BELLHOP (run by ``hilgate/channel/``, never imported) gives, per frequency, on a grid of source
depths × receiver depths × ranges: the transmission loss, and from its arrivals the delay of the first
arrival within ``threshold_db`` of the strongest, that arrival's slopes (``hilgate/channel/delays.py``)
and the RMS delay spread.  :class:`Fields` holds one frequency's grids as flat lists of floats with
uniform axes, so a lookup is a few multiplications and a dozen list reads (TL trilinear in source
depth, receiver depth and range; the delay from the nearest grid point), not a numpy call: that is the
whole cost an arrival adds.

A path (one sender, one receiver) is bound once (:meth:`BellhopChannel.bind`): the fields of the
sender's frequency and the receiver's loss model bound to the sender (``path.py``).  Each arrival
then asks :meth:`BellhopPath.at` with the ends' positions for an :class:`ArrivalLoss` (TL, delay, spread
there) that is the arrival's loss model: received level = SL − TL(range, source depth, receiver
depth), into the physical model's SNR → BER → PER chain.  A static pair asks once.

What is interpolated is the part the straight line does not explain: TL − 20·log10 R and the delay
− R/c̄ (R the slant distance, c̄ the mean sound speed), which stay smooth where the field bends sharply
near the source's depth at short range; the lookup adds the straight line back.  The delay is not
interpolated between grid points: which arrival is the first jumps from one point to the next, and a
blend of two is the delay of no path.  It is the nearest grid point's first arrival, followed to the
query along its own slopes (the same path at the neighbouring points).  Outside the grid:
depths are clamped to it; nearer than its first range the residual of the first range is used (TL
then falls spherically to 1 m, the delay to zero); beyond its last range TL goes on with 15·log r and
Thorp's absorption and the delay at the mean speed.  A receiver in a shadow (no
arrival within the grid) has TL :data:`TL_CAP` and the straight-line delay.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from .acoustics import db_to_linear, thorp_db_per_km
from .path import BoundPath, Undecodable, bind_path, front_of
from .physical import PhysicalErrorModel

if TYPE_CHECKING:
    from .environment import Water
    from .path import PathEnd
    from .trajectories import Vec3

__all__ = ["Fields", "BellhopChannel", "BellhopPath", "ArrivalLoss", "TL_CAP", "path_frequency_hz"]

TL_CAP = 250.0
"""Transmission loss (dB) where BELLHOP finds no sound (a shadow, a surface node): nothing decodes."""


class _Axis:
    """A uniform axis: first value, step, count (checked uniform: a lookup computes indices)."""

    __slots__ = ("x0", "step", "n", "last")

    def __init__(self, values: Sequence[float]):
        values = [float(v) for v in values]
        self.n = len(values)
        self.x0 = values[0]
        self.last = values[-1]
        self.step = (values[-1] - values[0]) / (self.n - 1) if self.n > 1 else 1.0
        for i, v in enumerate(values):
            if abs(v - (self.x0 + i * self.step)) > 1e-3 * abs(self.step) + 1e-6:
                raise ValueError(f"the grid's axis is not uniform at {v:g} (index {i})")

    def cell(self, x: float) -> tuple[int, float]:
        """The cell ``x`` is in: its first index and the weight of the next, clamped to the first and
        the last cell (an axis of two values at least)."""
        f = (x - self.x0) / self.step
        if f <= 0.0:
            return 0, 0.0
        if f >= self.n - 1:
            return self.n - 2, 1.0
        i = int(f)
        return i, f - i

    def nearest(self, x: float) -> tuple[int, float]:
        """The grid point nearest ``x`` (clamped to the axis) and how far ``x`` (clamped) is from it."""
        x = self.x0 if x < self.x0 else self.last if x > self.last else x
        i = int((x - self.x0) / self.step + 0.5) if self.n > 1 else 0
        i = self.n - 1 if i > self.n - 1 else i
        return i, x - (self.x0 + i * self.step)


class Fields:
    """One frequency's fields on one grid (see the module's doc).  ``tl``, ``first`` and ``spread``
    are nested sequences [source][depth][range] (numpy arrays are fine: they are flattened here);
    ``first`` and ``spread`` may be on a coarser grid of their own (``arrival_depths``,
    ``arrival_ranges``); ``first_slopes`` are the slopes of the first arrival's residual delay along
    receiver depth, range and source depth on that grid (s/m; none: the nearest point's delay, flat).
    ``fan``: the beams BELLHOP traced and how much doubling to them moved the TL at 99.9 % of the grid
    and at most (dB, NaN when the fan was given), as the preparation reports them."""

    __slots__ = ("frequency_hz", "sources", "depths", "ranges", "a_depths", "a_ranges", "tl", "first", "spread",
                 "first_dz", "first_dr", "first_ds", "fan",
                 "mean_speed", "alpha_db_per_m", "_tl_strides", "_a_strides")

    def __init__(self, frequency_hz: float, sources: Sequence[float], depths: Sequence[float],
                 ranges: Sequence[float], tl: Any, first: Any, spread: Any, mean_speed_mps: float,
                 arrival_depths: Sequence[float] | None = None, arrival_ranges: Sequence[float] | None = None,
                 first_slopes: tuple[Any, Any, Any] | None = None, fan: tuple[int, float, float] | None = None):
        self.frequency_hz = float(frequency_hz)
        self.fan = fan
        self.sources = _Axis(sources)
        self.depths = _Axis(depths)
        self.ranges = _Axis(ranges)
        self.a_depths = _Axis(depths if arrival_depths is None else arrival_depths)
        self.a_ranges = _Axis(ranges if arrival_ranges is None else arrival_ranges)
        self.mean_speed = float(mean_speed_mps)
        # what is interpolated is what the straight line does not explain (TL − 20·log10 R, delay − R/c,
        # R the slant distance): smooth where the field itself bends sharply (near the source's depth)
        tl = np.asarray(tl, dtype=np.float64)
        first = np.asarray(first, dtype=np.float64)
        for axis, what in ((self.depths, "depths"), (self.ranges, "ranges"), (self.a_depths, "arrival depths"),
                           (self.a_ranges, "arrival ranges")):
            if axis.n < 2:
                raise ValueError(f"the grid needs at least two {what}")
        self.tl = _flat(tl - 20.0 * np.log10(np.maximum(_slant(sources, depths, ranges), 1.0)),
                        (self.sources.n, self.depths.n, self.ranges.n), "tl")
        self.first = _flat(first - _slant(sources, self.a_depths_values(arrival_depths, depths),
                                          self.a_depths_values(arrival_ranges, ranges)) / self.mean_speed,
                           (self.sources.n, self.a_depths.n, self.a_ranges.n), "first")
        a_shape = (self.sources.n, self.a_depths.n, self.a_ranges.n)
        self.spread = _flat(spread, a_shape, "spread")
        if first_slopes is None:
            first_slopes = (np.zeros(a_shape),) * 3
        self.first_dz, self.first_dr, self.first_ds = (_flat(np.asarray(g, dtype=np.float64), a_shape, "first's slope")
                                                       for g in first_slopes)
        self.alpha_db_per_m = thorp_db_per_km(self.frequency_hz / 1000.0) / 1000.0
        self._tl_strides = (self.depths.n * self.ranges.n, self.ranges.n)
        self._a_strides = (self.a_depths.n * self.a_ranges.n, self.a_ranges.n)

    @staticmethod
    def a_depths_values(own: Sequence[float] | None, shared: Sequence[float]) -> Sequence[float]:
        return shared if own is None else own

    def _at(self, grids: tuple[list[float], ...], strides: tuple[int, int], depths: _Axis, ranges: _Axis,
            zs: float, zr: float, r: float) -> list[float]:
        """Trilinear interpolation of each of ``grids`` (all on the axes ``depths`` × ``ranges`` and
        ``strides``), clamped at the edges: each axis located once (this is the per-arrival cost: a
        handful of float operations and eight list reads a grid; the source's axis inline, as it may
        have one depth)."""
        sources = self.sources
        si, sj = strides
        # source depth
        n = sources.n
        f = (zs - sources.x0) / sources.step if n > 1 else 0.0
        if f <= 0.0:
            i, wi = 0, 0.0
        elif f >= n - 1:
            i, wi = n - 1, 0.0
        else:
            i = int(f)
            wi = f - i
        j, wj = depths.cell(zr)
        k, wk = ranges.cell(r)
        base = i * si + j * sj + k
        values = []
        for g in grids:
            a = g[base] + wk * (g[base + 1] - g[base])
            b = g[base + sj] + wk * (g[base + sj + 1] - g[base + sj])
            lower = a + wj * (b - a)
            if wi != 0.0:
                up = base + si
                a = g[up] + wk * (g[up + 1] - g[up])
                b = g[up + sj] + wk * (g[up + sj + 1] - g[up + sj])
                lower += wi * (a + wj * (b - a) - lower)
            values.append(lower)
        return values

    def _lookup(self, grid: list[float], strides: tuple[int, int], depths: _Axis, ranges: _Axis,
                zs: float, zr: float, r: float) -> float:
        return self._at((grid,), strides, depths, ranges, zs, zr, r)[0]

    def tl_and_delay(self, r: float, zs: float, zr: float) -> tuple[float, float]:
        """:meth:`tl_db` and :meth:`delay_s` at once (what an arrival asks)."""
        ranges = self.ranges
        if r > ranges.last:
            return self.tl_db(r, zs, zr), self.delay_s(r, zs, zr)
        residual = self._at((self.tl,), self._tl_strides, self.depths, ranges, zs, zr, r)[0]
        slant = math.hypot(r, zr - zs)
        spherical = 20.0 * math.log10(slant) if slant > 1.0 else 0.0
        tl = residual + spherical
        return (TL_CAP if tl > TL_CAP else 0.0 if tl < 0.0 else tl), self.delay_s(r, zs, zr)

    def tl_db(self, r: float, zs: float, zr: float) -> float:
        """Transmission loss (dB) at horizontal range ``r`` from a source at depth ``zs`` to a receiver
        at depth ``zr`` (metres)."""
        ranges = self.ranges
        slant = math.hypot(r, zr - zs)
        spherical = 20.0 * math.log10(slant) if slant > 1.0 else 0.0
        if r > ranges.last:
            edge = self._lookup(self.tl, self._tl_strides, self.depths, ranges, zs, zr, ranges.last)
            edge += 20.0 * math.log10(max(math.hypot(ranges.last, zr - zs), 1.0))
            return min(edge + 15.0 * math.log10(r / ranges.last) + self.alpha_db_per_m * (r - ranges.last), TL_CAP)
        residual = self._lookup(self.tl, self._tl_strides, self.depths, ranges, zs, zr, r)
        return min(max(residual + spherical, 0.0), TL_CAP)

    def _followed(self, zs: float, zr: float, r: float) -> float:
        """The residual delay of the nearest grid point's first arrival, followed to (``zs``, ``zr``,
        ``r``) along its slopes (clamped to the grid)."""
        i, ds = self.sources.nearest(zs)
        j, dz = self.a_depths.nearest(zr)
        k, dr = self.a_ranges.nearest(r)
        si, sj = self._a_strides
        at = i * si + j * sj + k
        return self.first[at] + dz * self.first_dz[at] + dr * self.first_dr[at] + ds * self.first_ds[at]

    def delay_s(self, r: float, zs: float, zr: float) -> float:
        """The first arrival's delay (s) at (``r``, ``zs``, ``zr``)."""
        ranges = self.a_ranges
        if r > ranges.last:
            edge = self._followed(zs, zr, ranges.last)
            return edge + math.hypot(ranges.last, zr - zs) / self.mean_speed + (r - ranges.last) / self.mean_speed
        return math.hypot(r, zr - zs) / self.mean_speed + self._followed(zs, zr, r)

    def spread_s(self, r: float, zs: float, zr: float) -> float:
        """The RMS delay spread (s) of the arrivals that count there (the edge value beyond the grid)."""
        ranges = self.a_ranges
        return self._lookup(self.spread, self._a_strides, self.a_depths, ranges, zs, zr,
                            min(max(r, ranges.x0), ranges.last))


def _slant(sources: Sequence[float], depths: Sequence[float], ranges: Sequence[float]) -> "np.ndarray":
    zs = np.asarray(sources, dtype=np.float64)[:, None, None]
    zr = np.asarray(depths, dtype=np.float64)[None, :, None]
    r = np.asarray(ranges, dtype=np.float64)[None, None, :]
    return np.hypot(r, zr - zs)


def _flat(values: Any, shape: tuple[int, int, int], name: str) -> list[float]:
    flat: list[float] = []
    if len(values) != shape[0]:
        raise ValueError(f"{name}: {len(values)} source depths, the grid has {shape[0]}")
    for plane in values:
        if len(plane) != shape[1]:
            raise ValueError(f"{name}: {len(plane)} depths, the grid has {shape[1]}")
        for row in plane:
            if len(row) != shape[2]:
                raise ValueError(f"{name}: {len(row)} ranges, the grid has {shape[2]}")
            flat.extend(float(v) for v in row)
    for v in flat:
        if not math.isfinite(v):
            raise ValueError(f"{name}: a value that is not finite (fill shadows before)")
    return flat


class ArrivalLoss:
    """One arrival's loss model: what the path's ends see at the geometry it was sent in (TL, delay,
    spread), with the error model's interface (``per``, ``rx_power``, ``per_sinr``; ``d`` is
    ignored: the geometry is already in)."""

    __slots__ = ("path", "tl_db", "delay", "spread", "received_db")

    def __init__(self, path: "BellhopPath", tl_db: float, delay: float, spread: float):
        self.path = path
        self.tl_db = tl_db
        self.delay = delay
        self.spread = spread
        model = path.model
        self.received_db = model.signal_db - tl_db if isinstance(model, PhysicalErrorModel) else -math.inf

    def snr_db(self) -> float:
        return self.received_db - self.path.model.noise_db

    def per(self, d: float, size: int) -> float:
        path = self.path
        if path.undecodable or (path.spread_limit is not None and self.spread > path.spread_limit):
            return 1.0
        model = path.model
        if not isinstance(model, PhysicalErrorModel):
            return model.per(d, size)
        return model.per_at_snr(self.received_db - model.noise_db, size)

    def rx_power(self, d: float) -> float:
        model = self.path.model
        if not isinstance(model, PhysicalErrorModel):
            return model.rx_power(d)
        return db_to_linear(self.received_db)

    def per_sinr(self, d: float, size: int, interference: float) -> float:
        path = self.path
        if path.undecodable or (path.spread_limit is not None and self.spread > path.spread_limit):
            return 1.0
        model = path.model
        sinr = self.received_db - 10.0 * math.log10(model.noise_power + interference)
        return model.per_at_snr(sinr, size)


class BellhopPath:
    """One (sender, receiver) pair on a BELLHOP channel: the fields of the sender's frequency, the
    receiver's model bound to the sender, the sea surface's z.  :meth:`at` is the per-arrival step."""

    __slots__ = ("fields", "model", "undecodable", "spread_limit", "surface_z", "constant_zero")

    def __init__(self, fields: Fields, model: Any, undecodable: bool = False, spread_limit: float | None = None,
                 surface_z: float = 0.0):
        self.fields = fields
        self.model = model
        self.undecodable = undecodable
        self.spread_limit = spread_limit
        self.surface_z = surface_z
        self.constant_zero = False

    def at(self, a: "Vec3", b: "Vec3") -> ArrivalLoss:
        """The reception of a frame sent from ``a`` to ``b`` (scene positions, z down): O(1)."""
        r = math.hypot(b[0] - a[0], b[1] - a[1])
        zs = a[2] - self.surface_z
        zr = b[2] - self.surface_z
        fields = self.fields
        spread = fields.spread_s(r, zs, zr) if self.spread_limit is not None else 0.0  # asked only where it counts
        tl, delay = fields.tl_and_delay(r, zs, zr)
        return ArrivalLoss(self, tl, delay, spread)

    # without positions (hilgate check's scan over distance): both ends at the grid's middle depth
    def per(self, d: float, size: int) -> float:
        return self._level(d).per(d, size)

    def rx_power(self, d: float) -> float:
        return self._level(d).rx_power(d)

    def per_sinr(self, d: float, size: int, interference: float) -> float:
        return self._level(d).per_sinr(d, size, interference)

    def _level(self, d: float) -> ArrivalLoss:
        z = self.surface_z + (self.fields.sources.x0 + self.fields.sources.last) / 2.0
        return self.at((0.0, 0.0, z), (d, 0.0, z))

    def __repr__(self) -> str:
        return f"BellhopPath({self.fields.frequency_hz:g} Hz, {self.model!r})"


class BellhopChannel:
    """The propagation of a channel with ``water:``: every path's delay and loss from BELLHOP's fields
    (``fields``: one :class:`Fields` per frequency the scene's senders use)."""

    positional = True  # (propagation.Propagation: each arrival is looked up at both ends' positions)
    distance_only = False  # (the water between two places depends on their depths, not only their distance)

    def __init__(self, water: "Water", fields: Sequence[Fields], min_delay_s: float = 0.0):
        if not fields:
            raise ValueError("a BELLHOP channel needs the fields of at least one frequency")
        self.water = water
        self.min_delay_s = min_delay_s  # the channel's, added to every delay as on any channel
        self.fields = sorted(fields, key=lambda f: f.frequency_hz)
        self.mean_speed = water.mean_speed_mps
        self.default = self.for_frequency(water.frequency_khz * 1000.0)

    def for_frequency(self, hz: float) -> Fields:
        """The prepared fields nearest to ``hz``."""
        return min(self.fields, key=lambda f: abs(math.log(f.frequency_hz / hz)))

    def frequency_of(self, sender: "PathEnd", receiver: "PathEnd") -> float:
        return path_frequency_hz(front_of(sender), front_of(receiver), self.water.frequency_khz * 1000.0)

    def delay(self, d: float, a: "Vec3 | None" = None, b: "Vec3 | None" = None) -> float:
        """The first arrival's delay between ``a`` and ``b`` at the water's default frequency; without
        positions, ``d`` at the mean sound speed."""
        if a is None or b is None:
            return self.min_delay_s + d / self.mean_speed
        z0 = self.water.surface_z_m
        return self.min_delay_s + self.default.delay_s(math.hypot(b[0] - a[0], b[1] - a[1]), a[2] - z0, b[2] - z0)

    def bind(self, sender: "PathEnd", receiver: "PathEnd") -> BoundPath:
        """The pair's :class:`BellhopPath` (band and modulation refusals as ``path.py`` decides)."""
        bound = bind_path(sender, receiver)
        model = bound.model
        undecodable = bound.refused is not None
        inner = model.inner if isinstance(model, Undecodable) else model
        fields = self.for_frequency(self.frequency_of(sender, receiver))
        limit = _tolerated_spread(receiver)
        return BoundPath(BellhopPath(fields, inner, undecodable, limit, self.water.surface_z_m), bound.refused,
                         bound.interferes)


def path_frequency_hz(tx: Any, rx: Any, default_hz: float) -> float:
    """The frequency a path is looked up at, from its ends' front ends (``physical.Acoustic`` or None):
    the centre of the sender's band inside the receiver's (where absorption is computed too), else
    of the sender's band, else of the receiver's, else ``default_hz``."""
    if tx is not None and rx is not None:
        overlap = rx.overlap_khz(tx)
        if overlap is not None:
            return (overlap[0] + overlap[1]) / 2.0 * 1000.0
    if tx is not None:
        return tx.centre_khz * 1000.0
    if rx is not None:
        return rx.centre_khz * 1000.0
    return default_hz


def _tolerated_spread(receiver: "PathEnd") -> float | None:
    front = front_of(receiver)
    return None if front is None else front.delay_spread_s
