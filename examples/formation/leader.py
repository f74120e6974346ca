#!/usr/bin/env python3
"""The leader's application: forwards the operator's waypoints to its autopilot (MAVLink
SET_POSITION_TARGET_LOCAL_NED) and broadcasts its own position to the followers every second."""

import argparse
import json
import os
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from hilgate.client import GliError, Link  # noqa: E402

POSITION_ONLY = 0b0000111111111000  # type_mask: use x, y, z only


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--link", default="leader_ac")
    parser.add_argument("--autopilot", default="udpout:127.0.0.1:14570")
    parser.add_argument("--period", type=float, default=1.0)
    parser.add_argument("--runtime-dir")
    parser.add_argument("--system-id", type=int, default=1, help="the vehicle's MAVLink system id")
    args = parser.parse_args()
    # This application runs beside the autopilot, as the vehicle's companion computer does: it speaks as
    # that (the vehicle's system id, MAV_COMP_ID_ONBOARD_COMPUTER), never as the pilot's ground station.
    autopilot = mavutil.mavlink_connection(args.autopilot, source_system=args.system_id,
                                           source_component=mavutil.mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)
    with Link.open(args.link, runtime_dir=args.runtime_dir) as link:
        next_broadcast = time.monotonic()
        while True:
            message = link.recv(timeout=max(0.0, next_broadcast - time.monotonic()))
            if message is not None:
                try:
                    waypoint = json.loads(message.data)["wp"]
                except (ValueError, KeyError):
                    continue
                autopilot.mav.set_position_target_local_ned_send(0, 1, 1, mavutil.mavlink.MAV_FRAME_LOCAL_NED,
                                                                 POSITION_ONLY, *waypoint, 0, 0, 0, 0, 0, 0, 0, 0)
            if time.monotonic() >= next_broadcast:
                next_broadcast += args.period
                pose = link.command({"class": "POSE"})  # where hilgate's pose board has us (from MAVLink)
                if pose.get("position"):
                    link.send(json.dumps({"leader": [round(v, 2) for v in pose["position"]]}).encode())


if __name__ == "__main__":
    try:
        main()
    except (KeyboardInterrupt, GliError, ConnectionError):
        pass  # the daemon stopped, or so did we
