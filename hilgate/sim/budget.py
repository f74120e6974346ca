"""What a scene's error models mean before it runs: for each pair of simulated links on one channel,
the distance now, the SNR (physical models), the PER of a frame there, and the distances at which the
PER crosses 0.1 and 0.9.  ``hilgate check`` prints it.

The crossings are found on the path's own model (the receiver's, bound to the sender as the medium
binds it: ``models/path.py``) by a scan over a logarithmic grid of distances and a bisection inside the first cell where
the PER reaches the level, so a curve that is not monotonic still reports where it *first* crosses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..models.bellhop_fields import BellhopPath
from ..models.path import bind_path
from ..models.physical import PhysicalErrorModel
from ..scene.specs import Scene
from .pose_sources import build_pose

__all__ = ["PairBudget", "link_budget", "crossing", "format_budget"]

DEFAULT_FRAME_BYTES = 64
GRID = 400
FAR_M = 100_000.0  # the scan stops here when the sender's range does not


@dataclass(frozen=True)
class PairBudget:
    src: str
    dst: str
    size: int
    d: float | None          # distance at t = 0 (None: a live vehicle without a pose yet)
    snr_db: float | None     # None for expression models
    per: float | None
    d_per_01: float | None   # None: never crosses within the range
    d_per_09: float | None
    range_m: tuple[float, float]
    refused: str | None = None  # the receiver takes none of the sender's frames (band, modulation)


def crossing(per, level: float, low: float, high: float) -> float | None:
    """The smallest distance in [low, high] where ``per(d)`` reaches ``level`` (None if it does not)."""
    low = max(low, 0.01)
    if high <= low:
        return low if per(low) >= level else None
    if per(low) >= level:
        return low
    ratio = (high / low) ** (1.0 / GRID)
    a = low
    for i in range(1, GRID + 1):
        b = high if i == GRID else low * ratio ** i
        if per(b) >= level:
            for _ in range(60):
                mid = (a + b) / 2.0
                if per(mid) >= level:
                    b = mid
                else:
                    a = mid
            return b
        a = b
    return None


def _frame_size(scene: Scene, link_id: str, default: int) -> int:
    for flow in scene.flows:
        if flow.src == link_id:
            return flow.size_bytes
    return default


def link_budget(scene: Scene, frame_bytes: int | None = None, limit: int | None = None,
                channels: dict[str, Any] | None = None) -> list[PairBudget]:
    """Pairs of simulated links (sender → receiver on its transmit channel) that can lose frames;
    error-free paths are left out.  With ``limit``, at most that many plus one (so the caller knows
    there are more): a scene of a thousand links has a million pairs.  ``channels``: the scene's
    channels made ready (``hilgate.channel.prepare``): a channel with water binds its pairs through
    BELLHOP's fields (SNR and PER at the two vehicles' places; the crossings with both at mid-depth)."""
    poses = {name: build_pose(vehicle) for name, vehicle in scene.vehicles.items()}
    sims = [link for link in scene.links.values() if link.backend == "sim"]
    rows = []
    crossings: dict[tuple, tuple[float | None, float | None]] = {}  # same model, size, range: same answer
    for sender in sims:
        size = frame_bytes or _frame_size(scene, sender.id, DEFAULT_FRAME_BYTES)
        rmin, rmax = sender.params.range_m
        for receiver in sims:
            if receiver is sender or receiver.params.rx_channel != sender.params.tx_channel:
                continue
            propagation = None if channels is None else channels[sender.params.tx_channel].propagation
            model, refused, _ = (bind_path if propagation is None else propagation.bind)(sender.params, receiver.params)
            a = poses[sender.vehicle].position(0.0)
            b = poses[receiver.vehicle].position(0.0)
            d = None if a is None or b is None else math.dist(a, b)
            here = model.at(a, b) if isinstance(model, BellhopPath) and a is not None and b is not None else None
            if refused is not None:
                per = None if d is None else 1.0
                rows.append(PairBudget(sender.id, receiver.id, size, d, None, per, None, None, (rmin, rmax), refused))
                if limit is not None and len(rows) > limit:
                    return rows
                continue
            if model.constant_zero:
                continue
            snr_of = getattr(model, "snr_db", None)  # (a column of the table: only physical models have an SNR)
            snr = snr_of(d) if snr_of is not None and d is not None else None
            if here is not None:
                snr = here.snr_db() if isinstance(model.model, PhysicalErrorModel) else None
            per = None if d is None else ((here or model).per(d, size) if rmin <= d <= rmax else 1.0)
            high = rmax if math.isfinite(rmax) else FAR_M
            key = (model, size, rmin, high)
            if key not in crossings:
                crossings[key] = (crossing(lambda x: model.per(x, size), 0.1, rmin, high),
                                  crossing(lambda x: model.per(x, size), 0.9, rmin, high))
            rows.append(PairBudget(sender.id, receiver.id, size, d, snr, per, *crossings[key], (rmin, rmax)))
            if limit is not None and len(rows) > limit:
                return rows
    return rows


def _metres(d: float | None, beyond: float) -> str:
    if d is None:
        return f"> {beyond:g}" if math.isfinite(beyond) else f"> {FAR_M:g}"
    return f"{d:.1f}" if d < 1000 else f"{d:.0f}"


def format_budget(rows: list[PairBudget]) -> str:
    """One line per pair: ``src -> dst  size  d  SNR  PER  PER=0.1 at  PER=0.9 at``; a pair whose
    receiver refuses the sender says why in the PER column (``1 (band)``) and has no crossings."""
    header = ("pair", "bytes", "d m", "SNR dB", "PER", "PER 0.1 at m", "PER 0.9 at m")
    table = [header]
    for row in rows:
        table.append((
            f"{row.src} -> {row.dst}", str(row.size),
            "-" if row.d is None else f"{row.d:.1f}",
            "-" if row.snr_db is None else f"{row.snr_db:.1f}",
            ("-" if row.per is None else f"{row.per:.3g}") + (f" ({row.refused})" if row.refused else ""),
            "-" if row.refused else _metres(row.d_per_01, row.range_m[1]),
            "-" if row.refused else _metres(row.d_per_09, row.range_m[1]),
        ))
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(r, widths)).rstrip() for r in table)


def budget_tables(scene: Scene, points: int = 24, limit: int = 2000) -> dict[str, Any]:
    """The link budget as tables over distance, for the live view's pair of modems (the page interpolates
    at the vehicles' distance): ``{"tables": [{"d", "per", "snr"}], "pairs": {"src>dst": table}}``.  Pairs
    whose model, frame size and range are alike share a table; error-free pairs and channels whose
    paths need BELLHOP's fields are left out (the page then says error-free, or shows no PER).  At most
    ``limit`` pairs: a scene of a thousand links has a million."""
    sims = [link for link in scene.links.values() if link.backend == "sim"]
    tables: list[dict[str, Any]] = []
    index: dict[tuple, int] = {}
    pairs: dict[str, int] = {}
    for sender in sims:
        size = _frame_size(scene, sender.id, DEFAULT_FRAME_BYTES)
        rmin, rmax = sender.params.range_m
        high = rmax if math.isfinite(rmax) else FAR_M
        for receiver in sims:
            if receiver is sender or receiver.params.rx_channel != sender.params.tx_channel:
                continue
            try:
                model, refused, _ = bind_path(sender.params, receiver.params)
            except Exception:  # a channel that needs its water's fields: no table
                continue
            if refused is not None or model.constant_zero:
                continue
            key = (model, size, rmin, high)
            if key not in index:
                low = max(rmin, 0.1)
                ds = [low * (high / low) ** (i / (points - 1)) for i in range(points)] if high > low else [low]
                snr_of = getattr(model, "snr_db", None)  # (only physical models have an SNR)
                index[key] = len(tables)
                tables.append({"size": size, "d": [round(d, 4) for d in ds],
                               "per": [_finite(model.per(d, size)) for d in ds],
                               "snr": [_finite(snr_of(d)) for d in ds] if snr_of is not None else None})
            pairs[f"{sender.id}>{receiver.id}"] = index[key]
            if len(pairs) >= limit:
                return {"tables": tables, "pairs": pairs}
    return {"tables": tables, "pairs": pairs}


def _finite(value: Any) -> float | None:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return round(value, 6) if math.isfinite(value) else None
