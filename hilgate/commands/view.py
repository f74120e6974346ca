"""``hilgate view [TRACE]``: the operator's page for a trace, or the running daemon's address (:mod:`.viewing`)."""

from __future__ import annotations

import argparse

from .daemon_client import control_request
from .options import web_address

NAME = "view"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate view``'s parser, among ``sub``'s."""
    p = sub.add_parser("view", help="the operator's view in a browser: play a trace (play, pause, speed, a time "
                                    "slider), or without TRACE print the running daemon's address (hilgate run --web)")
    p.add_argument("trace", nargs="?", help="a trace of hilgate sim or hilgate run")
    p.add_argument("--web", metavar="[ADDR:]PORT", type=web_address, default="0",
                   help="where to serve it (default: any free port on loopback)")
    p.add_argument("--run", metavar="ID|N", help="which run of a daemon's trace (its id, or 1 for the first, -1 the "
                                                 "last; default the last)")
    p.add_argument("--scene", help="the scene, for a trace that names none (hilgate sim's traces)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a value of --scene, as for sim")
    p.add_argument("--token-file", metavar="FILE",
                   help="pages prove this file's token (default: a new one for this run, printed in the address)")
    p.add_argument("--runtime-dir", help="without TRACE: the daemon's runtime directory")
    return p


def run(args: argparse.Namespace) -> int:
    from .viewing import live_address, serve_trace

    if args.trace is None:
        return live_address(args, lambda request: control_request(args, request))
    return serve_trace(args)
