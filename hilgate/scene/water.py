"""Reading a channel's ``water:``: the environment a BELLHOP channel traces its rays through.

Checked like every other key (``FILE:LINE: key.path: what is wrong``), and whole: a profile that does
not start at the surface, depths that go back up, a bottom shallower than a profile point, a grid
too large to compute, are refused here, before anything runs BELLHOP.
"""

from __future__ import annotations

from ..models.environment import RUNS, SEDIMENTS, SURFACES, Bottom, Water, mackenzie_speed
from .checks import Fields, choice, describe, integer, items, join_path, number
from .yaml_nodes import Node

__all__ = ["WATER_KEYS", "water_spec"]

WATER_KEYS = ("depth_m", "sound_speed", "temperature_c", "salinity_ppt", "bottom", "surface", "surface_z_m",
              "bathymetry", "grid", "beams", "run", "threshold_db", "frequency_khz")
GRID_KEYS = ("range_m", "ranges", "depths", "source_depths", "arrival_ranges", "arrival_depths")
BOTTOM_KEYS = ("speed_mps", "density", "attenuation_db_per_wavelength")
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


def water_spec(node: Node, path: str) -> Water:
    """The ``water:`` of a channel at ``path``."""
    f = Fields(node, path, WATER_KEYS)
    depth = f.get("depth_m", number(above=0, maximum=11_000))
    if "sound_speed" in f and "temperature_c" in f:
        raise f.child("temperature_c").error(f.sub("temperature_c"), "give sound_speed or temperature_c, not both")
    if "sound_speed" in f:
        profile = f.get("sound_speed", lambda n, p: _pairs(n, p, (0, 11_000), (1300, 1800), "depth_m, speed_mps"))
    elif "temperature_c" in f:
        temperature = f.get("temperature_c", lambda n, p: _pairs(n, p, (0, 11_000), (-2, 40), "depth_m, celsius"))
        salinity = f.get("salinity_ppt", number(0, 45), 35.0)
        profile = [(z, mackenzie_speed(t, salinity, z)) for z, t in temperature]
    else:
        raise f.error("missing 'sound_speed' ([[depth_m, speed_mps], …]) or 'temperature_c' ([[depth_m, °C], …])")
    where = "sound_speed" if "sound_speed" in f else "temperature_c"
    if profile[0][0] != 0.0:
        raise f.child(where).error(f.sub(where), f"must start at the surface (depth 0), not {profile[0][0]:g} m")
    if profile[-1][0] > depth:
        raise f.child(where).error(f.sub(where), f"goes to {profile[-1][0]:g} m, below the bottom at {depth:g} m")
    if "salinity_ppt" in f and "temperature_c" not in f:
        raise f.child("salinity_ppt").error(f.sub("salinity_ppt"), "only with temperature_c (sound_speed is given)")
    bathymetry = f.get("bathymetry", lambda n, p: _pairs(n, p, (0, 1e6), (0.1, 11_000), "range_m, depth_m"), [])
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
        beams=f.get("beams", integer(0, 100_000), default.beams),
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
