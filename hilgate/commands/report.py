"""``hilgate report TRACE --out DIR``: figures and tables of a trace, and of summaries side by side
(``--water SCENE``: :mod:`.water_figures`)."""

from __future__ import annotations

import argparse
import sys

NAME = "report"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate report``'s parser, among ``sub``'s."""
    p = sub.add_parser("report", help="figures (and --csv tables) of a trace, and of summaries side by side")
    p.add_argument("trace", help="a trace written by --trace")
    p.add_argument("summaries", nargs="*", help="summaries written by --summary, compared flow by flow")
    p.add_argument("--out", required=True, help="the folder for the figures and index.html")
    p.add_argument("--vehicles", nargs="+", help="vehicles whose distances to plot (default: the first four)")
    p.add_argument("--csv", action="store_true", help="also write the tables behind the figures")
    p.add_argument("--title", help="the page's title")
    p.add_argument("--window", type=float, nargs=2, metavar=("START", "END"), help="only these seconds of the trace")
    p.add_argument("--format", dest="formats", action="append", choices=["svg", "pdf"],
                   help="also write each figure as SVG or PDF (vector, for a paper; repeatable)")
    p.add_argument("--width", type=float, metavar="INCHES",
                   help="draw the figures this wide, e.g. 3.5 for one column of a paper (default 9, the bars of "
                        "many flows wider; text keeps its size, tick labels are thinned where they would overlap)")
    p.add_argument("--dpi", type=float, metavar="N",
                   help="the PNGs' resolution in dots per inch (default 300, what journals ask; 600 or more for "
                        "line art); SVG and PDF are vector")
    p.add_argument("--captions", action="store_true",
                   help="also draw each figure's caption under it (it is always in the file's metadata and "
                        "index.html; a journal sets captions itself)")
    p.add_argument("--run", metavar="ID|N", help="a trace the daemon appended to across restarts holds several runs: "
                                                 "this one (its id, or 1 for the first, -1 the last; default the last)")
    p.add_argument("--water", metavar="SCENE", help="also draw each channel with water's BELLHOP transmission loss "
                                                    "with the vehicles' tracks over it (water-CHANNEL.png)")
    return p


def run(args: argparse.Namespace) -> int:
    from ..report.figures import DPI, report
    from ..report.tracedata import pick_run, trace_runs
    from ..report.tracefile import TraceError

    try:
        runs = trace_runs(args.trace)
        run = pick_run(runs, args.run)
        if len(runs) > 1:
            which = "the last" if args.run is None else f"number {run.index}"
            print(f"{args.trace} holds {len(runs)} runs of the daemon; showing {which}: run {run.id} started "
                  f"{run.start} (scene {run.scene}); choose another with --run ID or --run N", file=sys.stderr)
        formats = tuple(dict.fromkeys(["png", *(args.formats or [])]))
        dpi = DPI if args.dpi is None else args.dpi
        written = report(args.trace, args.summaries, args.out, args.vehicles, args.csv, args.title,
                         tuple(args.window) if args.window else None, run if len(runs) > 1 else None, formats,
                         args.width, dpi, args.captions)
        if args.water:
            from .water_figures import water_figures

            drawn = water_figures(args.trace, args.water, args.out, formats, dpi)
            if not drawn:
                print(f"{args.water}: no channel with water, or no simulated sender with a pose in the trace: "
                      f"no field drawn", file=sys.stderr)
            written = drawn + written
    except TraceError as exc:  # (ReportError is one): a line that names the file, the line and what is wrong
        print(f"hilgate: {exc}", file=sys.stderr)
        return 1
    print(f"{len(written)} files in {args.out}: open {written[-1]}")
    return 0
