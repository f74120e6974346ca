"""``hilgate reload``: the running daemon reads its scene file again (as SIGHUP)."""

from __future__ import annotations

import argparse
import sys

from .daemon_client import control_request, open_control
from .options import EXIT_SCENE

NAME = "reload"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate reload``'s parser, among ``sub``'s."""
    p = sub.add_parser("reload", help="make the running daemon read its scene file again (as SIGHUP); links whose "
                                      "keys changed are reconfigured in place, applications stay connected")
    p.add_argument("--timeout", type=float, default=60.0, metavar="S",
                   help="wait at most S seconds for the daemon's answer (default 60)")
    p.add_argument("--runtime-dir")
    return p


def run(args: argparse.Namespace) -> int:
    """SIGHUP without knowing the daemon's PID: the RELOAD request, answered once the scene file is
    applied or refused (the daemon then keeps the scene it had)."""
    with open_control(args) as control:
        control.settimeout(args.timeout)
        answer = control.request({"class": "RELOAD"})
    if not answer.get("ok"):
        print(f"hilgate: reload refused, the daemon keeps its scene: {answer.get('error')}", file=sys.stderr)
        return EXIT_SCENE
    links = control_request(args, {"class": "STATUS"}).get("links", [])
    listed = ", ".join(f"{link['id']}={link['backend']}" for link in links)
    print(f"reloaded: {len(links)} links ({listed})")
    return 0
