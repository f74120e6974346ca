"""The water a channel's sound travels through: depth, sound-speed profile, bottom, surface, and the grid
on which a ray tracer (BELLHOP) samples the field once, so that each arrival only looks it up.

A scene gives it under a channel (``channels: {acoustic: {water: {...}}}``, ``hilgate/scene/water.py``
reads it); ``hilgate/channel/`` turns it into an Acoustics Toolbox environment file, runs BELLHOP on it
as a separate program and reads its output; :mod:`.bellhop_fields` looks the fields up per arrival.
Everything here is plain data and formulas (no I/O): the spec is hashable, and its hash (with the
frequency) names the cached fields on disk, so a changed profile never reuses an old field.

Simplifications, stated once: the bottom is a fluid half-space (no shear), and the water depth is one
number per field: a range-dependent bottom is given as a profile of depth against range from the
sender (BELLHOP's 2-D bathymetry, the same along every bearing), not as a map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Bottom", "SEDIMENTS", "SURFACES", "RUNS", "Water", "mackenzie_speed", "munk_speed", "munk_profile",
           "NEAR_BOUNDARY_M", "AUTO_BEAMS"]


@dataclass(frozen=True)
class Bottom:
    """A fluid half-space under the water: compressional speed, density (g/cm³) and attenuation
    (dB per wavelength), as the Acoustics Toolbox's ``'A'`` bottom takes them."""

    speed_mps: float
    density: float
    attenuation_db_per_wavelength: float
    name: str = ""


SEDIMENTS: dict[str, Bottom] = {
    # Jensen, Kuperman, Porter & Schmidt, Computational Ocean Acoustics (2nd ed., 2011), table 1.3
    # (compressional speed as a ratio to 1500 m/s water; shear left out: a fluid half-space)
    "clay": Bottom(1500.0, 1.5, 0.2, "clay"),
    "silt": Bottom(1575.0, 1.7, 1.0, "silt"),
    "sand": Bottom(1650.0, 1.9, 0.8, "sand"),
    "gravel": Bottom(1800.0, 2.0, 0.6, "gravel"),
    "moraine": Bottom(1950.0, 2.1, 0.4, "moraine"),
    "chalk": Bottom(2400.0, 2.2, 0.2, "chalk"),
    "limestone": Bottom(3000.0, 2.4, 0.1, "limestone"),
    "basalt": Bottom(5250.0, 2.7, 0.1, "basalt"),
}
"""Named sediments a scene may give as ``bottom: sand``."""

SURFACES = ("vacuum", "rigid")
"""``vacuum``: a pressure-release sea surface (the usual one); ``rigid``: a hard lid (an ice cover, a tank)."""

RUNS = ("incoherent", "coherent", "semicoherent")
"""How BELLHOP sums the beams into transmission loss: incoherent (phases dropped: a smooth field, what a
packet's average power sees; the default), coherent (interference fringes), semicoherent (Lloyd mirror)."""


def mackenzie_speed(temperature_c: float, salinity_ppt: float, depth_m: float) -> float:
    """Sound speed in sea water (m/s), Mackenzie (JASA 70(3), 807–812, 1981); valid for 2–30 °C,
    25–40 ‰ and 0–8 000 m."""
    t, s, d = temperature_c, salinity_ppt - 35.0, depth_m
    return (1448.96 + 4.591 * t - 5.304e-2 * t * t + 2.374e-4 * t ** 3 + 1.340 * s + 1.630e-2 * d
            + 1.675e-7 * d * d - 1.025e-2 * t * s - 7.139e-13 * t * d ** 3)


def munk_speed(depth_m: float, axis_m: float = 1300.0, scale_m: float = 1300.0, c_axis: float = 1500.0,
               epsilon: float = 0.00737) -> float:
    """Munk's canonical deep-water profile (JASA 55, 220, 1974): c = c₁(1 + ε(η − 1 + e^−η)),
    η = 2(z − z₁)/B."""
    eta = 2.0 * (depth_m - axis_m) / scale_m
    return c_axis * (1.0 + epsilon * (eta - 1.0 + math.exp(-eta)))


MUNK_STEP_M = 50.0
"""The tabulation of :func:`munk_profile`: BELLHOP interpolates c linearly between rows, and at 50 m
the chords of Munk's curve are within 0.06 m/s of it over 5 000 m (the Toolbox's own Munk cases
tabulate every 250 m)."""


def munk_profile(bottom_m: float) -> tuple[tuple[float, float], ...]:
    """Munk's profile (:func:`munk_speed`, canonical parameters) tabulated from the surface to
    ``bottom_m`` in equal steps of at most :data:`MUNK_STEP_M`: what ``sound_speed: munk`` means."""
    n = max(1, math.ceil(bottom_m / MUNK_STEP_M))
    return tuple((bottom_m * i / n, munk_speed(bottom_m * i / n)) for i in range(n + 1))


NEAR_BOUNDARY_M = 2.0
"""An incoherent field's receivers stay this far from the surface and the bottom (a tenth of the water
in water shallower than 20 m; half a layer where layers are thicker): BELLHOP's geometric beams within
their own width of a boundary lose part of themselves there and converge only as that width shrinks,
while the incoherent field (intensities summed, the surface's image included) is there what it is a
little deeper.  A modem nearer a boundary takes the field at this depth (spreading from its own)."""

AUTO_BEAMS = "auto"
"""``beams``: the fan is found by convergence (``hilgate/channel/beams.py``)."""


@dataclass(frozen=True)
class Water:
    """What a BELLHOP channel needs besides the frequency (which comes from each sender's modem).

    ``sound_speed`` holds (depth, speed) pairs from the surface to ``depth_m``; ``bathymetry`` (depth
    against range from the sender) replaces the flat bottom when given.  The grid: ``range_m`` far in
    ``ranges`` steps (from ``range_m / ranges``), receivers at ``depths`` depths from the surface to
    the deepest bottom, sources in ``source_depths`` bins (a sender's depth takes the field of the
    nearest bins, interpolated).  ``threshold_db``: an arrival counts for the delay when it is within
    this many dB of the strongest at that point."""

    depth_m: float
    sound_speed: tuple[tuple[float, float], ...]
    bottom: Bottom = SEDIMENTS["sand"]
    surface: str = "vacuum"
    bathymetry: tuple[tuple[float, float], ...] = ()
    surface_z_m: float = 0.0       # the scene's z (NED, down) of the sea surface
    range_m: float = 5000.0
    ranges: int = 501
    depths: int = 51
    source_depths: int = 11
    arrival_ranges: int = 101      # the arrivals' grid (delay and spread vary slowly: a coarser one)
    arrival_depths: int = 26
    beams: int | str = AUTO_BEAMS  # the fan's beams: auto (by convergence), or a number (0: BELLHOP chooses)
    run: str = "incoherent"
    threshold_db: float = 20.0
    frequency_khz: float = 10.0    # for senders whose modem has no acoustic front end

    @property
    def deepest_m(self) -> float:
        """The deepest water anywhere (the receiver grid reaches it)."""
        return max([self.depth_m] + [d for _, d in self.bathymetry])

    @property
    def mean_speed_mps(self) -> float:
        """The depth-averaged sound speed (what a straight line away from every arrival travels at)."""
        points = self.sound_speed
        if len(points) == 1:
            return points[0][1]
        total = 0.0
        for (z0, c0), (z1, c1) in zip(points, points[1:]):
            total += (z1 - z0) * (c0 + c1) / 2.0
        span = points[-1][0] - points[0][0]
        return total / span if span > 0 else points[0][1]

    def source_grid(self) -> list[float]:
        """The source depths BELLHOP is run at: the centres of ``source_depths`` equal bins of the
        water column (a source exactly at a pressure-release surface radiates nothing)."""
        step = self.depth_m / self.source_depths
        return [(i + 0.5) * step for i in range(self.source_depths)]

    @property
    def boundary_margin_m(self) -> float:
        """How far an incoherent run's receivers stay from the surface and the bottom (at least):
        :data:`NEAR_BOUNDARY_M`, or a tenth of water shallower than 20 m."""
        return min(NEAR_BOUNDARY_M, self.deepest_m / 10.0)

    def bottom_at(self, r: float) -> float:
        """The bottom's depth at range ``r`` from a sender: ``depth_m``, or the bathymetry linear between
        its rows and level beyond them (as BELLHOP reads the ``.bty`` hilgate writes)."""
        points = sorted(self.bathymetry)
        if not points:
            return self.depth_m
        if r <= points[0][0]:
            return points[0][1]
        for (r0, d0), (r1, d1) in zip(points, points[1:]):
            if r <= r1:
                return d0 + (d1 - d0) * (r - r0) / (r1 - r0)
        return points[-1][1]

    def receiver_grid(self, n: int | None = None) -> list[float]:
        """Receiver depths: ``depths`` (or ``n``) points at the centres of equal layers from the
        surface to the deepest bottom; in an incoherent run, in equal steps from :data:`NEAR_BOUNDARY_M`
        below the surface to as far above the deepest bottom, where the layers are thinner than twice
        that (coherent runs keep the surface's interference there: Lloyd's mirror)."""
        n = self.depths if n is None else n
        layer = self.deepest_m / n
        margin = max(layer / 2.0, self.boundary_margin_m) if self.run == "incoherent" else 0.0
        if margin <= layer / 2.0 or n < 2:
            return [(i + 0.5) * layer for i in range(n)]
        step = (self.deepest_m - 2.0 * margin) / (n - 1)
        return [margin + i * step for i in range(n)]

    def range_grid(self, n: int | None = None) -> list[float]:
        """Receiver ranges: ``ranges`` (or ``n``) steps of ``range_m / n`` (no column at 0, where a
        point source's field is infinite)."""
        n = self.ranges if n is None else n
        step = self.range_m / n
        return [(i + 1) * step for i in range(n)]
