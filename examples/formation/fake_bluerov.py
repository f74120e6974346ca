#!/usr/bin/env python3
"""A BlueROV2 for people without one: ArduSub's MAVLink as seen from the topside, made with pymavlink.

It reports LOCAL_POSITION_NED, ATTITUDE and GLOBAL_POSITION_INT at 10 Hz to hilgate (``--to``) and
flies towards the last SET_POSITION_TARGET_LOCAL_NED it received (``--listen``) at ``--speed`` m/s, as
ArduSub in GUIDED mode would; with no target it holds its place."""

import argparse
import math
import os
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--to", default="udpout:127.0.0.1:14560", help="where hilgate listens")
    parser.add_argument("--listen", default="udpin:127.0.0.1:14570", help="where position targets arrive")
    parser.add_argument("--start", type=float, nargs=3, default=[0.0, 0.0, 2.0])
    parser.add_argument("--speed", type=float, default=0.3)
    parser.add_argument("--seconds", type=float, default=3600)
    args = parser.parse_args()
    out = mavutil.mavlink_connection(args.to, source_system=1, source_component=1)
    commands = mavutil.mavlink_connection(args.listen, source_system=1, source_component=1)
    position, target = list(args.start), None
    boot = last = time.monotonic()
    while time.monotonic() - boot < args.seconds:
        message = commands.recv_match(type="SET_POSITION_TARGET_LOCAL_NED", blocking=True, timeout=0.1)
        if message is not None:
            target = [message.x, message.y, message.z]
        now = time.monotonic()
        dt, last = now - last, now
        if target is not None:
            gap = math.dist(position, target)
            step = min(gap, args.speed * dt)
            if gap > 0:
                position = [p + (q - p) * step / gap for p, q in zip(position, target)]
        ms = int((now - boot) * 1000)
        out.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_SUBMARINE, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0)
        out.mav.local_position_ned_send(ms, *position, 0, 0, 0)
        out.mav.attitude_send(ms, 0, 0, 0, 0, 0, 0)
        out.mav.global_position_int_send(ms, 0, 0, 0, int(-position[2] * 1000), 0, 0, 0, 0)


if __name__ == "__main__":
    main()
