"""A scene as plain JSON, for the trace: what the daemon's ``run`` and ``reload`` lines carry.

A trace must say what the scene was at each moment (which links were real, where each rode, what
their modems were), since the file it came from changes or disappears: ``hilgate fit`` and
``hilgate report`` read the scene from these lines, never from the file as it is later.  The view is
the scene *resolved* (presets, ``--set`` overrides and defaults applied), with every number finite or
``null`` (an unbounded range, a flow without a stop), so that a strict JSON reader takes it.  The
hash is of the view itself (sorted keys, no spaces): two lines with the same hash describe the same
scene, and a reader can check it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from typing import Any

from ..models.physical import PhysicalErrorModel
from ..models.propagations import implied
from . import LinkSpec, Scene

__all__ = ["scene_view", "link_view", "view_hash", "link_changes", "error_view"]

HASH_CHARS = 16  # of sha256's 64 hex digits: enough to tell a lab's scene versions apart


def _plain(value: Any) -> Any:
    """JSON-ready: tuples as lists, dataclasses as objects, non-finite numbers as null."""
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # by name: every field of a dataclass
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    return str(value)


def error_view(model: Any) -> dict[str, Any]:
    """A link's error model, complete enough to build it again: ``{"unit", "expr"}`` for an expression
    of distance, ``{"kind": "physical", "env", "acoustic", "bitrate_bps", "sender", "sender_bitrate_bps"}``
    for the physical model (the arguments of :class:`hilgate.models.physical.PhysicalErrorModel`; the
    sender the receiver's model stands for until the medium binds a path to its real one)."""
    if isinstance(model, PhysicalErrorModel):
        return {"kind": "physical", "env": _plain(model.env), "acoustic": _plain(model.acoustic),
                "bitrate_bps": _plain(model.bitrate_bps), "sender": _plain(model.sender),
                "sender_bitrate_bps": _plain(model.sender_bitrate_bps)}
    return {"unit": model.unit, "expr": model.expression.text}


def link_view(link: LinkSpec) -> dict[str, Any]:
    p = link.params
    params = {f.name: _plain(getattr(p, f.name)) for f in dataclasses.fields(p)  # (by name: every field of a dataclass)
              if f.name not in ("address", "tx_channel", "rx_channel", "error")}
    params["error"] = error_view(p.error)
    view = {
        "vehicle": link.vehicle,
        "backend": link.backend,
        "address": p.address,
        "tx_channel": p.tx_channel,
        "rx_channel": p.rx_channel,
        "packet": link.packet,
        "model": link.model,
        "mac": {"protocol": link.mac.protocol, **{str(k): _plain(v) for k, v in link.mac.params}},
        "params": params,
    }
    if link.options:
        view["options"] = {str(k): _plain(v) for k, v in link.options}
    if link.emulate:
        view["emulate"] = {str(k): _plain(v) for k, v in link.emulate}
    if link.host is not None:
        view["host"] = link.host
    if link.usbl is not None:
        view["usbl"] = _plain(link.usbl)
    if tuple(link.gli) != ("mq", "socket"):
        view["gli"] = list(link.gli)
    return view


def scene_view(scene: Scene) -> dict[str, Any]:
    """The scene as the trace records it: name, seed, channels, vehicles (their pose source and host),
    links (resolved) and flows."""
    return {
        "name": scene.name,
        "seed": scene.seed,
        "channels": {name: {"speed_mps": _plain(c.speed_mps), "min_delay_s": _plain(c.min_delay_s),
                            # (a model the water does not imply: one a package added)
                            **({"propagation": c.model} if c.model != implied(c.water) else {})}
                     for name, c in scene.channels.items()},
        "vehicles": {name: {"source": v.pose.source_name, **({"host": v.host} if v.host else {})}
                     for name, v in scene.vehicles.items()},
        "links": {link_id: link_view(link) for link_id, link in scene.links.items()},
        "flows": [_plain(flow) for flow in scene.flows],
    }


def view_hash(view: dict[str, Any]) -> str:
    text = json.dumps(view, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:HASH_CHARS]


def link_changes(before: dict[str, Any] | None, after: dict[str, Any] | None) -> dict[str, Any]:
    """What differs between two views of one link: ``{"added": true}``, ``{"removed": true}``, or each
    changed key as ``[before, after]`` (the parameters under ``params``, key by key)."""
    if before is None:
        return {"added": True}
    if after is None:
        return {"removed": True}
    changed: dict[str, Any] = {}
    for key in dict.fromkeys([*before, *after]):
        b, a = before.get(key), after.get(key)
        if b == a:
            continue
        if key == "params" and isinstance(b, dict) and isinstance(a, dict):
            changed[key] = {k: [b.get(k), a.get(k)] for k in dict.fromkeys([*b, *a]) if b.get(k) != a.get(k)}
        else:
            changed[key] = [b, a]
    return changed
