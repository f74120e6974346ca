#!/usr/bin/env python3
"""The operator at the buoy: sends the leader its next waypoint over the acoustic link, again and again
(acoustic messages get lost), until the route is done."""

import argparse
import json
import time

from hilgate.client import GliError, Link

ROUTE = [[0, 0, 2], [3, 0, 2], [3, 3, 2], [0, 3, 2]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--link", default="buoy_ac")
    parser.add_argument("--leader", type=int, default=1, help="the leader's modem address")
    parser.add_argument("--leg-seconds", type=float, default=12.0)
    parser.add_argument("--legs", type=int, default=3, help="how many legs of the square to fly")
    parser.add_argument("--runtime-dir")
    args = parser.parse_args()
    with Link.open(args.link, runtime_dir=args.runtime_dir) as link:
        for waypoint in ROUTE[1 : 1 + args.legs]:
            until = time.monotonic() + args.leg_seconds
            while time.monotonic() < until:
                link.send(json.dumps({"wp": waypoint}).encode(), dst=args.leader)
                time.sleep(2.0)


if __name__ == "__main__":
    try:
        main()
    except (KeyboardInterrupt, GliError, ConnectionError):
        pass  # the daemon stopped, or so did we
