"""What a channel with water means for each pair of modems, before the scene runs: BELLHOP's TL and the
PER of a frame at a few ranges and receiver depths, the sender at its vehicle's depth at t = 0.
``hilgate check`` prints it under the link budget; a range-only model would print one row, this
prints a table because the receiver's depth changes the loss as much as the range does."""

from __future__ import annotations

import math
from typing import Any, Mapping

from ..models.bellhop_fields import BellhopPath
from ..models.physical import PhysicalErrorModel
from ..scene.specs import Scene
from .budget import DEFAULT_FRAME_BYTES, _frame_size
from .pose_sources import build_pose

__all__ = ["water_tables", "RANGE_FRACTIONS", "DEPTH_FRACTIONS"]

RANGE_FRACTIONS = (0.1, 0.25, 0.5, 1.0)
"""The ranges of the table, as fractions of the channel's grid (``grid.range_m``)."""
DEPTH_FRACTIONS = (0.1, 0.5, 0.9)
"""The receiver depths, as fractions of the water's depth."""


def water_tables(scene: Scene, channels: Mapping[str, Any], frame_bytes: int | None = None,
                 limit: int | None = None) -> list[str]:
    """One block of lines per (sender, receiver) pair of simulated links on a channel with water
    (at most ``limit`` blocks)."""
    blocks: list[str] = []
    sims = [link for link in scene.links.values() if link.backend == "sim"]
    poses = {name: build_pose(vehicle) for name, vehicle in scene.vehicles.items()}
    for sender in sims:
        channel = channels[sender.params.tx_channel]
        if not channel.propagation.positional:
            continue
        water = channel.water
        size = frame_bytes or _frame_size(scene, sender.id, DEFAULT_FRAME_BYTES)
        a = poses[sender.vehicle].position(0.0)
        zs = (a[2] - water.surface_z_m) if a is not None else water.depth_m / 2.0
        for receiver in sims:
            if receiver is sender or receiver.params.rx_channel != sender.params.tx_channel:
                continue
            bound = channel.propagation.bind(sender.params, receiver.params)
            path = bound.model
            if bound.refused is not None or not isinstance(path, BellhopPath):
                continue
            head = (f"{sender.id} -> {receiver.id} on {channel.name}: {path.fields.frequency_hz / 1000:g} kHz, "
                    f"source at {zs:.0f} m, {size} bytes; TL dB / PER by range (columns) and receiver depth (rows)")
            blocks.append("\n".join([head, *_grid(path, water, zs, size)]))
            if limit is not None and len(blocks) >= limit:
                return blocks
    return blocks


def _grid(path: Any, water: Any, zs: float, size: int) -> list[str]:
    """A pair's table: TL and PER at fractions of the water's range (columns) and depth (rows), the source at
    depth ``zs``."""
    ranges = [f * water.range_m for f in RANGE_FRACTIONS]
    depths = [f * water.depth_m for f in DEPTH_FRACTIONS]
    lines = ["  depth m" + "".join(f"{_metres(r):>18}" for r in ranges)]
    for zr in depths:
        cells = []
        for r in ranges:
            here = path.at((0.0, 0.0, zs + water.surface_z_m), (r, 0.0, zr + water.surface_z_m))
            per = here.per(math.hypot(r, zr - zs), size) if isinstance(path.model, PhysicalErrorModel) else None
            cells.append(f"{here.tl_db:.1f} / " + _per(per))
        lines.append(f"  {zr:>7.0f}" + "".join(f"{c:>18}" for c in cells))
    return lines


def _metres(r: float) -> str:
    return f"{r / 1000:g} km" if r >= 1000 else f"{r:g} m"


def _per(per: float | None) -> str:
    if per is None:
        return "-"
    return "<1e-6" if 0.0 < per < 1e-6 else f"{per:.2g}"
