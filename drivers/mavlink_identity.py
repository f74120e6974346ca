"""Who hilgate is on a vehicle's MAVLink network: an onboard peripheral, never a ground station.

ArduSub takes any HEARTBEAT from system ``SYSID_MYGCS`` (255 by default) as a sign that its ground
station is alive; a hilgate that sent as system 255 would keep the GCS failsafe from firing after the
pilot's link was lost.  So hilgate sends nothing a scene did not ask for, and when it sends (a
heartbeat, message-rate requests, position feedback) it does so as a companion computer does: the
vehicle's own system id (which ArduPilot accepts even with ``SYSID_ENFORCE``), a component id of its
own that is neither the autopilot's nor a ground station's, MAV_TYPE_ONBOARD_CONTROLLER.

Pure: no pymavlink here, so validating a scene does not import it.
"""

from __future__ import annotations

from dataclasses import dataclass

GCS_SYSTEM_ID = 255  # ArduPilot's SYSID_MYGCS default, what ground stations send as
AUTOPILOT_COMPONENT_ID = 1  # MAV_COMP_ID_AUTOPILOT1
GCS_COMPONENT_ID = 190  # MAV_COMP_ID_MISSIONPLANNER, what ground stations send as
DEFAULT_COMPONENT_ID = 192  # MAV_COMP_ID_ONBOARD_COMPUTER2 (191 is often the companion's own router)
DEFAULT_HEARTBEAT_HZ = 1.0


@dataclass(frozen=True)
class Identity:
    system_id: int
    component_id: int = DEFAULT_COMPONENT_ID


def system_problem(system_id: int) -> str | None:
    """Why hilgate must not send as ``system_id`` (None if it may)."""
    if system_id == GCS_SYSTEM_ID:
        return (f"{GCS_SYSTEM_ID} is the ground station's system id (ArduSub's SYSID_MYGCS): a heartbeat from it "
                "would keep the GCS failsafe from firing; use the vehicle's own system id")
    if not 1 <= system_id <= 254:
        return "a system id is 1-254"
    return None


def component_problem(component_id: int) -> str | None:
    """Why hilgate must not send as ``component_id`` (None if it may)."""
    if component_id == AUTOPILOT_COMPONENT_ID:
        return "component 1 is the autopilot's own; give hilgate a component id of its own (default 192)"
    if component_id == GCS_COMPONENT_ID:
        return "component 190 is a ground station's (MAV_COMP_ID_MISSIONPLANNER); use e.g. 192 (the default)"
    if not 1 <= component_id <= 255:
        return "a component id is 1-255"
    return None


def identity_problem(identity: Identity) -> str | None:
    return system_problem(identity.system_id) or component_problem(identity.component_id)
