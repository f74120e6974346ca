"""``hilgate fit TRACE``: an ``error:`` block fitted to the frames of a run (:mod:`.fitting`)."""

from __future__ import annotations

import argparse
import sys

from .options import EXIT_SCENE

NAME = "fit"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate fit``'s parser, among ``sub``'s."""
    p = sub.add_parser("fit", help="fit an error: block (loss against distance) to the frames of a trace")
    p.add_argument("trace", help="a trace (JSON lines) of hilgate run with real links, or of hilgate sim with "
                                 "--simulated")
    p.add_argument("--scene", help="the scene of the run (default: the one the trace's run line names)")
    p.add_argument("--link", action="append", metavar="ID",
                   help="fit the frames these links received (default: every receiver); repeatable")
    p.add_argument("--model", choices=("power", "logistic", "physical"), default="power",
                   help="power: BER = a*d^b per bit (default); logistic in d; physical: effective source level "
                        "and spreading k of the receivers' error: {kind: physical}")
    p.add_argument("--simulated", action="store_true",
                   help="the trace is of a simulated run: fit its simulated links' frames")
    p.add_argument("--run", help="which run of a daemon's trace (id or number; default: the last)")
    p.add_argument("--pose-gap", type=float, default=2.0, metavar="S",
                   help="leave out frames with no pose sample within S seconds (default 2)")
    p.add_argument("--window", type=float, default=5.0, metavar="S",
                   help="real links: a frame counts as received when the receiver traced it within S seconds")
    p.add_argument("--bins", type=int, default=10, help="distance bins in the table and plot (default 10)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the fit, its band and the binned data (matplotlib)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a value of the scene, as for check and sim")
    return p


def run(args: argparse.Namespace) -> int:
    from .fitting import plot_fit, print_fit, run_fit
    from ..report.tracefile import TraceError

    import numpy as np

    try:
        with np.errstate(all="ignore"):  # degenerate data give infinite intervals, printed as such
            result = run_fit(args.trace, args.scene, args.model, args.link, args.simulated, args.run, args.pose_gap,
                             args.window, tuple(args.overrides))
            print_fit(result, sys.stdout, args.bins)
        if args.plot:
            plot_fit(result, args.plot, args.bins)
            print(f"\nplot: {args.plot}")
    except TraceError as exc:  # (FitError is one)
        print(f"hilgate: fit: {exc}", file=sys.stderr)
        return EXIT_SCENE
    return 0
