"""The ``hilgate`` command: check, sim, run, status, send, listen, emulate, report."""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Callable

from . import __version__
from .located import SceneError

log = logging.getLogger(__name__)

EXIT_SCENE = 2


def _add_scene_args(parser: argparse.ArgumentParser, optional: bool = False) -> None:
    if optional:
        parser.add_argument("scene", nargs="?", help="scene file (YAML)")
    else:
        parser.add_argument("scene", help="scene file (YAML)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                        help="override a scene value, '*' matches every key at its level "
                             "(e.g. --set 'links.*.mac.protocol=s-fama'); repeatable")


def cmd_check(args: argparse.Namespace) -> int:
    from .scene import load_scene, scene_summary

    scene = load_scene(args.scene, args.overrides)
    print(scene_summary(scene))
    print("ok")
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    from .scene import load_scene
    from .simulate import simulate, write_summary
    from .table import format_summary

    scene = load_scene(args.scene, args.overrides)
    if args.until is not None and args.until <= 0:
        raise SceneError("--until", 0, "", f"must be positive, not {args.until:g}")
    trace_path = args.trace if args.trace is not None else scene.trace_file
    trace = open(trace_path, "w", encoding="utf-8", buffering=1 << 20) if trace_path else None
    try:
        progress = sys.stderr.isatty() and not args.quiet
        summary = simulate(scene, until=args.until, seed=args.seed, trace=trace, progress=progress)
    finally:
        if trace is not None:
            trace.close()
    if args.summary:
        write_summary(summary, args.summary)
    if not args.quiet:
        print(format_summary(summary))
        if trace_path:
            print(f"\ntrace: {trace_path}")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "check": cmd_check,
    "sim": cmd_sim,
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hilgate",
        description="Hardware-in-the-loop gateway for underwater communications: dccomms GLI links routed "
                    "to real modems or to a simulated channel.",
    )
    parser.add_argument("--version", action="version", version=f"hilgate {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser("check", help="validate a scene file and print what it contains")
    _add_scene_args(p)

    p = sub.add_parser("sim", help="run a scene in virtual time, as fast as possible")
    _add_scene_args(p)
    p.add_argument("--until", type=float, help="simulated seconds (default: the scene's duration_s)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's seed)")
    p.add_argument("--trace", help="write the event trace (JSON lines) here")
    p.add_argument("--summary", help="write the summary (JSON) here")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing at the end")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    try:
        return COMMANDS[args.command](args)
    except SceneError as exc:
        print(f"hilgate: {exc}", file=sys.stderr)
        return EXIT_SCENE
    except KeyboardInterrupt:
        return 130
    except OSError as exc:
        print(f"hilgate: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
