"""``hilgate sim SCENE``: a scene in virtual time, as fast as possible, with its trace and summary."""

from __future__ import annotations

import argparse
import sys

from ..scene.yaml_nodes import SceneError
from .options import add_scene_args

NAME = "sim"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate sim``'s parser, among ``sub``'s."""
    p = sub.add_parser("sim", help="run a scene in virtual time, as fast as possible")
    add_scene_args(p)
    p.add_argument("--until", type=float, help="simulated seconds (default: the scene's duration_s)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's seed)")
    p.add_argument("--trace", help="write the event trace (JSON lines) here")
    p.add_argument("--summary", help="write the summary (JSON) here")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing at the end")
    return p


def run(args: argparse.Namespace) -> int:
    from ..core.outputs import OutputError, open_output, output_problem
    from ..scene.load import load_scene
    from ..sim.simulate import simulate, write_summary
    from ..report.tables import format_summary

    scene = load_scene(args.scene, args.overrides, plugins=args.plugins, preset_dirs=args.preset_dirs)
    if args.until is not None and args.until <= 0:
        raise SceneError("--until", 0, "", f"must be positive, not {args.until:g}")
    trace_path = args.trace if args.trace is not None else scene.trace_file
    if args.summary:  # refused before the run, not after it
        problem = output_problem(args.summary, "summary")
        if problem is not None:
            raise OutputError(problem)
    trace = open_output(trace_path, "trace", append=False, buffering=1 << 20) if trace_path else None
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
