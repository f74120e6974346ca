"""Reading a channel's ``water:``: the environment a BELLHOP channel traces its rays through.

Checked like every other key (``FILE:LINE: key.path: what is wrong``), and whole, because BELLHOP takes
contradictory water without a word and computes nonsense from it: a profile that does not start at the
surface or stops above the deepest bottom (it was extended with its last speed), depths that go back
up, a bathymetry whose depth under the sender is not ``depth_m`` (the sources were put in the sediment:
every cell 250 dB), a grid too large to compute, are refused here, before anything runs BELLHOP.
Whether the modems are in the water is :mod:`.in_water`'s (it needs the vehicles and links).
"""

from __future__ import annotations

from ..models.environment import AUTO_BEAMS, RUNS, SEDIMENTS, SURFACES, Bottom, Water, mackenzie_speed, munk_profile
from .checks import Fields, choice, describe, integer, items, join_path, number
from .yaml_nodes import Node

__all__ = ["WATER_KEYS", "NAMED_PROFILES", "water_spec"]

WATER_KEYS = ("depth_m", "sound_speed", "temperature_c", "salinity_ppt", "bottom", "surface", "surface_z_m",
              "bathymetry", "grid", "beams", "run", "threshold_db", "frequency_khz")
GRID_KEYS = ("range_m", "ranges", "depths", "source_depths", "arrival_ranges", "arrival_depths")
BOTTOM_KEYS = ("speed_mps", "density", "attenuation_db_per_wavelength")
NAMED_PROFILES = ("munk",)
"""Profiles a scene may name (``sound_speed: munk``: :func:`~hilgate.models.environment.munk_profile`)."""
MAX_POINTS = 2_000_000
"""Receivers × source depths of one run: beyond this a run takes minutes and its files gigabytes."""


def _pairs(node: Node, path: str, first: tuple[float, float], second: tuple[float, float],
           what: str) -> list[tuple[float, float]]:
    """A list of [a, b] rows with a strictly increasing a."""
    rows = items(node, path)
    if not rows:
        raise node.error(path, f"must list at least one [{what}] row")
    out: list[tuple[float, float]] = []
    for i, row in enumerate(rows):
        where = join_path(path, i)
        if not row.is_list or len(row.value) != 2:
            raise row.error(where, f"must be a [{what}] row, not {describe(row)}")
        a = number(*first)(row.value[0], join_path(where, 0))
        b = number(*second)(row.value[1], join_path(where, 1))
        if out and a <= out[-1][0]:
            raise row.error(where, f"{a:g} must be beyond the row before ({out[-1][0]:g}): rows go outwards")
        out.append((a, b))
    return out


def _bottom(node: Node, path: str) -> Bottom:
    if isinstance(node.value, str):
        named = SEDIMENTS.get(node.value)
        if named is None:
            raise node.error(path, f"must be one of {', '.join(SEDIMENTS)} or a mapping of {', '.join(BOTTOM_KEYS)}, "
                                   f"not {describe(node)}")
        return named
    f = Fields(node, path, BOTTOM_KEYS)
    return Bottom(f.get("speed_mps", number(100, 10_000)), f.get("density", number(above=0, maximum=25)),
                  f.get("attenuation_db_per_wavelength", number(0, 50), 0.0))


def _profile(f: Fields, key: str, bottom: float, note: str, what: str,
             limits: tuple[float, float]) -> list[tuple[float, float]]:
    """``sound_speed`` or ``temperature_c``: one value for every depth, a named profile (speeds only), or
    rows from the surface down to the deepest bottom."""
    node, path = f.child(key), f.sub(key)
    value = node.value
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        one = number(*limits)(node, path)
        return [(0.0, one), (bottom, one)]
    if isinstance(value, str) and key == "sound_speed":
        if value in NAMED_PROFILES:
            return list(munk_profile(bottom))
        import difflib  # only for a scene with a mistake

        close = difflib.get_close_matches(value, NAMED_PROFILES, n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise node.error(path, f"must be {' or '.join(NAMED_PROFILES)}, one speed in m/s or [[depth_m, "
                               f"speed_mps], …] rows, not {describe(node)}{hint}")
    rows = _pairs(node, path, (0, 11_000), limits, what)
    if rows[0][0] != 0.0:
        raise node.error(path, f"must start at the surface (depth 0), not {rows[0][0]:g} m")
    if rows[-1][0] > bottom:
        raise node.error(path, f"goes to {rows[-1][0]:g} m, below the bottom at {bottom:g} m{note}")
    if rows[-1][0] < bottom:
        one = f"{key}: {rows[0][1]:g}"
        raise node.error(path, f"stops at {rows[-1][0]:g} m, above the bottom at {bottom:g} m{note}: list it down "
                               f"to {bottom:g} m (or give one value for every depth, {one})")
    return rows


def _beams(node: Node, path: str) -> int | str:
    """``auto`` (the fan found by convergence) or a number of beams (0: the program chooses)."""
    if node.value == AUTO_BEAMS:
        return AUTO_BEAMS
    if isinstance(node.value, str):
        raise node.error(path, f"must be {AUTO_BEAMS} or a number of beams (0: BELLHOP chooses), not {describe(node)}")
    return integer(0, 100_000)(node, path)


def water_spec(node: Node, path: str) -> Water:
    """The ``water:`` of a channel at ``path``."""
    f = Fields(node, path, WATER_KEYS)
    bathymetry = f.get("bathymetry", lambda n, p: _pairs(n, p, (0, 1e6), (0.1, 11_000), "range_m, depth_m"), [])
    if "depth_m" in f:
        depth = f.get("depth_m", number(above=0, maximum=11_000))
    elif bathymetry:
        depth = bathymetry[0][1]
    else:
        raise f.error("missing required key 'depth_m' (the water's depth under a sender; or give 'bathymetry')")
    if bathymetry and bathymetry[0][1] != depth:
        first = f.child("bathymetry").value[0]
        where = join_path(join_path(f.sub("bathymetry"), 0), 1)
        raise first.value[1].error(where, f"the bottom under the sender (range 0: this first row's depth) is "
                                          f"{bathymetry[0][1]:g} m deep, but depth_m is {depth:g}: give them the same "
                                          "depth (BELLHOP's sources stand in depth_m of water)")
    bottom = max([depth] + [d for _, d in bathymetry])
    note = "" if bottom == depth else " (the deepest in the bathymetry)"
    if "sound_speed" in f and "temperature_c" in f:
        raise f.child("temperature_c").error(f.sub("temperature_c"), "give sound_speed or temperature_c, not both")
    if "sound_speed" in f:
        profile = _profile(f, "sound_speed", bottom, note, "depth_m, speed_mps", (1300, 1800))
    elif "temperature_c" in f:
        temperature = _profile(f, "temperature_c", bottom, note, "depth_m, celsius", (-2, 40))
        salinity = f.get("salinity_ppt", number(0, 45), 35.0)
        profile = [(z, mackenzie_speed(t, salinity, z)) for z, t in temperature]
    else:
        raise f.error("missing 'sound_speed' (munk, one speed, or [[depth_m, speed_mps], …]) or 'temperature_c' "
                      "([[depth_m, °C], …])")
    if "salinity_ppt" in f and "temperature_c" not in f:
        raise f.child("salinity_ppt").error(f.sub("salinity_ppt"), "only with temperature_c (sound_speed is given)")
    grid = f.child("grid")
    default = Water(depth, ())
    g = Fields(grid, f.sub("grid"), GRID_KEYS) if grid is not None else None

    def grid_value(key: str, check, fallback):
        return g.get(key, check, fallback) if g is not None else fallback

    range_m = grid_value("range_m", number(above=0, maximum=1e6), default.range_m)
    water = Water(
        depth_m=depth,
        sound_speed=tuple(profile),
        bottom=f.get("bottom", _bottom, SEDIMENTS["sand"]),
        surface=f.get("surface", choice(*SURFACES), "vacuum"),
        bathymetry=tuple(bathymetry),
        surface_z_m=f.get("surface_z_m", number(-11_000, 11_000), 0.0),
        range_m=range_m,
        ranges=grid_value("ranges", integer(2, 100_000), default.ranges),
        depths=grid_value("depths", integer(2, 10_000), default.depths),
        source_depths=grid_value("source_depths", integer(1, 1_000), default.source_depths),
        arrival_ranges=grid_value("arrival_ranges", integer(2, 100_000), default.arrival_ranges),
        arrival_depths=grid_value("arrival_depths", integer(2, 10_000), default.arrival_depths),
        beams=f.get("beams", _beams, AUTO_BEAMS),
        run=f.get("run", choice(*RUNS), "incoherent"),
        threshold_db=f.get("threshold_db", number(above=0, maximum=200), 20.0),
        frequency_khz=f.get("frequency_khz", number(above=0, maximum=1000), 10.0),
    )
    for n_depths, n_ranges, key in ((water.depths, water.ranges, "grid.ranges"),
                                    (water.arrival_depths, water.arrival_ranges, "grid.arrival_ranges")):
        if n_depths * n_ranges * water.source_depths > MAX_POINTS:
            raise (grid or node).error(join_path(path, key), f"{water.source_depths} source depths × {n_depths} depths × "
                                       f"{n_ranges} ranges is more than {MAX_POINTS} points to compute")
    return water
