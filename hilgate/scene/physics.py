"""Reading the physical channel model's keys: ``error: {kind: physical, …}`` and a link's ``acoustic:``.

The environment (water, noise, how collisions are judged) lives in the error block because it is
where the link is; the modem's acoustic front end (band, source level, modulation) lives in
``acoustic:`` because it comes with the modem, so presets give it (``models/evologics-*.yaml``).
"""

from __future__ import annotations

from ..models.acoustics import MODULATIONS
from ..models.errormodel import UNITS
from ..models.physical import ABSORPTION, COLLISIONS, LEVEL_DB, NOISE_BAND, Acoustic, Environment
from .checks import Fields, choice, integer, items, join_path, number, describe
from .yaml_nodes import Node

__all__ = ["ERROR_KINDS", "ERROR_KEYS", "ACOUSTIC_KEYS", "error_kind", "physical_environment", "acoustic_params"]

ERROR_KINDS = ("expr", "physical")
PHYSICAL_KEYS = ("absorption", "spreading", "shipping", "wind_mps", "noise_floor_db", "noise_band",
                 "temperature_c", "salinity_ppt", "depth_m", "ph", "collisions", "capture_db")
ERROR_KEYS = ("kind", "unit", "expr") + PHYSICAL_KEYS
ACOUSTIC_KEYS = ("band_khz", "source_level_db", "level", "modulation", "coding_gain_db", "decodes", "delay_spread_s")


def error_kind(node: Node, path: str) -> str:
    """The ``kind`` of an error block (``expr`` when absent), checked."""
    f = Fields(node, path, ERROR_KEYS)
    return f.get("kind", choice(*ERROR_KINDS), "expr")


def physical_environment(node: Node, path: str) -> Environment:
    f = Fields(node, path, ERROR_KEYS)
    for key in ("unit", "expr"):
        if key in f:
            raise f.child(key).error(f.sub(key), f"only for kind: expr (kind: physical computes the PER; "
                                                 f"units: {', '.join(UNITS)})")
    default = Environment()
    return Environment(
        absorption=f.get("absorption", choice(*ABSORPTION), default.absorption),
        spreading=f.get("spreading", number(1, 2), default.spreading),
        shipping=f.get("shipping", number(0, 1), default.shipping),
        wind_mps=f.get("wind_mps", number(0, 100), default.wind_mps),
        noise_floor_db=f.get("noise_floor_db", number(-100, 200), None),
        noise_band=f.get("noise_band", choice(*NOISE_BAND), default.noise_band),
        temperature_c=f.get("temperature_c", number(-2, 40), default.temperature_c),
        salinity_ppt=f.get("salinity_ppt", number(0, 45), default.salinity_ppt),
        depth_m=f.get("depth_m", number(0, 11000), default.depth_m),
        ph=f.get("ph", number(6, 10), default.ph),
        collisions=f.get("collisions", choice(*COLLISIONS), default.collisions),
        capture_db=f.get("capture_db", number(-50, 100), default.capture_db),
    )


def _band(node: Node, path: str) -> tuple[float, float]:
    if not node.is_list or len(node.value) != 2:
        raise node.error(path, f"must be [low, high] in kHz, not {describe(node)}")
    low = number(above=0, maximum=10_000)(node.value[0], join_path(path, 0))
    high = number(above=0, maximum=10_000)(node.value[1], join_path(path, 1))
    if high <= low:
        raise node.error(path, f"high {high:g} kHz must be above low {low:g} kHz")
    return (low, high)


def _decodes(node: Node, path: str) -> tuple[str, ...]:
    """``decodes: [bpsk, qpsk]``: modulations the modem decodes besides its own ``modulation``."""
    check = choice(*MODULATIONS)
    chosen: list[str] = []
    for i, item in enumerate(items(node, path)):
        value = check(item, join_path(path, i))
        if value in chosen:
            raise item.error(join_path(path, i), f"{value} is given twice")
        chosen.append(value)
    return tuple(chosen)


def acoustic_params(node: Node, path: str) -> Acoustic:
    f = Fields(node, path, ACOUSTIC_KEYS)
    return Acoustic(
        band_khz=f.get("band_khz", _band),
        source_level_db=f.get("source_level_db", number(0, 260)),
        level=f.get("level", integer(0, len(LEVEL_DB) - 1), 0),
        modulation=f.get("modulation", choice(*MODULATIONS), "bpsk"),
        coding_gain_db=f.get("coding_gain_db", number(0, 30), 0.0),
        decodes=f.get("decodes", _decodes, ()),
        delay_spread_s=f.get("delay_spread_s", number(above=0, maximum=60), None),
    )
