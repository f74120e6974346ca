#!/usr/bin/env python3
"""A follower's application: keeps its vehicle at its slot of the square formation, relative to the last
leader position it heard, by steering its (simulated) vehicle through hilgate."""

import argparse
import json

from hilgate.client import GliError, Link


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--link", required=True)
    parser.add_argument("--slot", type=float, nargs=3, required=True, help="offset from the leader (m, NED)")
    parser.add_argument("--runtime-dir")
    args = parser.parse_args()
    with Link.open(args.link, runtime_dir=args.runtime_dir) as link:
        while True:
            message = link.recv(timeout=None)
            try:
                leader = json.loads(message.data)["leader"]
            except (ValueError, KeyError, TypeError):
                continue
            target = [l + s for l, s in zip(leader, args.slot)]
            link.command({"class": "GOTO", "position": target})


if __name__ == "__main__":
    try:
        main()
    except (KeyboardInterrupt, GliError, ConnectionError):
        pass  # the daemon stopped, or so did we
