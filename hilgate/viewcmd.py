"""``hilgate view``: the operator's page for a trace (``hilgate view TRACE``), or the address of a running
daemon's (``hilgate view``, for ``hilgate run --web``).  Wires the trace reader, the scene loader and
the web door together (above the rooms, as ``fitcmd.py`` is).

The address printed carries the token in its fragment (``#token=…``): a browser never sends a
fragment to a server, and the page keeps the token for its tab only.  A trace is served with a new
token of its own unless ``--token-file`` names one; the daemon's address carries the daemon's token,
which only a member of its group can read.
"""

from __future__ import annotations

import argparse
import os
import secrets
import signal
import sys
import threading
from typing import Any, Callable
from urllib.parse import quote

from .gli.token import TokenCheck, read_token
from .report.tracedata import load_trace, pick_run, trace_runs
from .report.tracefile import TraceError
from .scene.yaml_nodes import SceneError

__all__ = ["serve_trace", "live_address", "address_with_token"]


def address_with_token(url: str, token: bytes) -> str:
    return f"{url}#token={quote(token.decode('ascii'), safe='')}"


def live_address(args: argparse.Namespace, request: Callable[[dict], dict]) -> int:
    """The running daemon's web view, with its token (read from the file its status names)."""
    status = request({"class": "STATUS"})
    web = status.get("web") if isinstance(status, dict) else None
    if not isinstance(web, dict):
        print("hilgate: the running daemon serves no web view: start it with --web [ADDR:]PORT", file=sys.stderr)
        return 1
    token = read_token(web["token_file"])
    print(address_with_token(web["url"], token))
    return 0


def _scenes(args: argparse.Namespace, trace: Any) -> list[tuple[float, dict]]:
    if trace.scenes:
        if args.scene:
            print(f"hilgate: {args.trace} carries its scene (run and reload lines): --scene is not used",
                  file=sys.stderr)
        return trace.scenes
    if not args.scene:
        raise SceneError(args.trace, 0, "", "this trace names no scene (hilgate sim writes none): give the scene "
                                            "it ran with, --scene FILE")
    from .scene import load_scene
    from .scene.view import scene_view

    return [(0.0, scene_view(load_scene(args.scene, args.overrides)))]


def serve_trace(args: argparse.Namespace, stop: threading.Event | None = None,
                announce: Callable[[str], Any] | None = None) -> int:
    """Serve the trace's player until SIGINT/SIGTERM (or ``stop``)."""
    from .web.replay import Replay
    from .web.server import WebServer, parse_web

    try:
        runs = trace_runs(args.trace)
        run = pick_run(runs, args.run)
        trace = load_trace(args.trace, None, run if len(runs) > 1 else None)
    except TraceError as exc:
        print(f"hilgate: view: {exc}", file=sys.stderr)
        return 1
    replay = Replay(trace, _scenes(args, trace), os.path.basename(args.trace))
    if args.token_file:  # (its path is not said to pages that have not proved it)
        token, hint = read_token(args.token_file), "the token of the file hilgate view was given"
    else:
        token, hint = secrets.token_hex(32).encode(), "the address hilgate view printed"
    host, port = parse_web(args.web)
    server = WebServer(host, port, TokenCheck(token, args.token_file or ""), replay=replay, token_hint=hint,
                       token_file=args.token_file or "")
    stop = stop or threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)} \
        if threading.current_thread() is threading.main_thread() else {}
    try:
        server.start()
        which = f", run {run.id}" if len(runs) > 1 else ""
        line = (f"playing {args.trace}{which}: {len(replay.packets)} frames, {replay.end:.1f} s of model time, at "
                f"{address_with_token(server.url, token)} (Ctrl-C stops)")
        (announce or (lambda text: print(text, flush=True)))(line)
        stop.wait()
    finally:
        server.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0
