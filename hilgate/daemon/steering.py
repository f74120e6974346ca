"""What a client may ask about its link's vehicle: where it is (``POSE``) and, for a vehicle ``controlled`` by
applications (:class:`hilgate.models.controlled.Controlled`), where it goes (``GOTO``, ``VELOCITY``, ``STOP``):
vehicle steering, apart from the link that carries the request (:meth:`.router.Router.command`)."""

from __future__ import annotations

import math
from typing import Any

from ..models.controlled import Controlled


def vehicle_request(world: Any, vehicle: str, request: dict, now: float) -> dict[str, Any]:
    """``request`` about ``vehicle`` at ``now``:

    - ``{"class": "POSE"}``: the vehicle's position now;
    - ``{"class": "GOTO", "position": [x, y, z]}``, ``{"class": "VELOCITY", "velocity": [vx, vy, vz]}``,
      ``{"class": "STOP"}``: steer a ``controlled`` vehicle (at most at its maximum speed)."""
    kind = request.get("class")
    pose = world.poses.get(vehicle) if world else None
    if kind == "POSE":
        position = pose.position(now) if pose is not None else None
        return {"class": "POSE", "vehicle": vehicle, "t": round(now, 6),
                "position": None if position is None else [round(v, 6) for v in position]}
    if kind in ("GOTO", "VELOCITY", "STOP"):
        if not isinstance(pose, Controlled):
            return {"class": "ERROR", "error": f"vehicle {vehicle!r} is not controlled by applications"}
        try:
            if kind == "STOP":
                pose.stop(now)
            else:
                key = "position" if kind == "GOTO" else "velocity"
                values = tuple(float(v) for v in request[key])
                if len(values) != 3 or not all(map(math.isfinite, values)):
                    raise ValueError
                (pose.go_to if kind == "GOTO" else pose.set_velocity)(now, values)
        except (KeyError, TypeError, ValueError):
            return {"class": "ERROR", "error": f"{kind} needs {'position' if kind == 'GOTO' else 'velocity'}: "
                                               "a list of three numbers"}
        world.medium.topology_changed()
        return {"class": kind, "ok": True, "t": round(now, 6)}
    return {"class": "ERROR", "error": f"unknown request {kind!r}"}
