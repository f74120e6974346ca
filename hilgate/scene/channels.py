"""Reading a scene's ``channels:``: each channel's speed, its delay floor, its water and the propagation model
it names (``propagation:``, from :data:`hilgate.models.propagations.PROPAGATIONS`, as ``mac:`` names a MAC).

Without ``propagation:`` a channel is what it always was: the straight line, or BELLHOP when it gives
``water:``.  A model that takes the water needs it; the straight line refuses it (the water would be
ignored: a scene must not look like it traces rays when it does not).  Installed packages add models
through the ``hilgate.propagation`` entry points, merged here, where every scene's names are read.
"""

from __future__ import annotations

from ..core.tables import merge_entry_points
from ..models.medium import Channel
from ..models.propagations import PROPAGATIONS, PropagationModel, implied
from .checks import Fields, join_path, number, quote, text, unknown_key_message
from .water import water_spec
from .yaml_nodes import Node

__all__ = ["CHANNEL_KEYS", "channel_spec", "propagation_name"]

CHANNEL_KEYS = ("speed_mps", "min_delay_s", "water", "propagation")

merge_entry_points("hilgate.propagation", PROPAGATIONS, lambda row: isinstance(row, PropagationModel))


def propagation_name(node: Node, path: str) -> str:
    """A ``propagation:`` value: a model of the registry (a "did you mean" for a misspelt one)."""
    name = text(node, path)
    if name not in PROPAGATIONS:
        hint = unknown_key_message(name, list(PROPAGATIONS)).replace("unknown key", f"unknown propagation model {quote(name)}")
        raise node.error(path, hint)
    return name


def channel_spec(name: str, node: Node) -> Channel:
    path = join_path("channels", name)
    f = Fields(node, path, CHANNEL_KEYS)
    water = f.get("water", water_spec, None)
    model = f.get("propagation", propagation_name, implied(water))
    if PROPAGATIONS[model].water and water is None:
        raise f.child("propagation").error(f.sub("propagation"), f"{model} traces the channel's water: give water:")
    if water is not None and not PROPAGATIONS[model].water:
        raise f.child("water").error(f.sub("water"), f"propagation {model} takes no water (give propagation: "
                                     f"{', '.join(n for n, row in PROPAGATIONS.items() if row.water)}, or no water)")
    return Channel(name, f.get("speed_mps", number(above=0)), f.get("min_delay_s", number(0), 0.0), water,
                   model=model)
