"""BELLHOP as a program: ``python tools/bellhop_run.py ROOT [--report FILE]`` reads ``ROOT.env`` and
writes ``ROOT.shd`` (a transmission-loss run) or ``ROOT.arr`` (an arrivals run), as the Acoustics
Toolbox's ``bellhop.exe ROOT`` does.

It runs under the Python of a separate environment that holds pelagic (GPL-3.0-or-later; ``make
.venv-bellhop`` makes one), never under hilgate's: hilgate (MIT) does not import it, it starts this
script as a process and reads the files it writes with its own readers (docs/channel-models.md).  This
file is not part of the installed package.

``--report FILE`` also writes what pelagic itself computed, as JSON (the tests check hilgate's readers
against it): the field's transmission loss, or every arrival.
"""

import argparse
import json
import math
import os
import shutil
import sys
import tempfile


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", help="the run's file root: ROOT.env in, ROOT.shd or ROOT.arr out")
    parser.add_argument("--report", help="also write pelagic's own values to this JSON file")
    args = parser.parse_args()
    import pelagic  # the separate environment's; hilgate's has none

    env = args.root + ".env"
    try:
        result = pelagic.bellhop.load(env).run()
    except pelagic.PelagicError as exc:
        print(f"bellhop_run: {env}: {exc}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory(dir=os.path.dirname(os.path.abspath(env))) as out:
        result.write_native(out)
        produced = [name for name in os.listdir(out) if name.endswith((".shd", ".arr"))]
        for name in produced:
            shutil.move(os.path.join(out, name), args.root + os.path.splitext(name)[1])
    if args.report:
        report = {"version": pelagic.__version__, "frequency_hz": result.frequency_hz}
        if result.field is not None:
            field = result.field
            loss = field.transmission_loss()
            report.update(ranges=field.ranges_m.tolist(), depths=field.depths_m.tolist(),
                          sources=field.source_depths_m.tolist(),
                          tl_db=[[[None if not math.isfinite(v) else float(v) for v in row] for row in plane]
                                 for plane in loss.tolist()])
        arrivals = result.arrivals
        if arrivals is not None and len(arrivals.amplitude):
            report.update(receiver_offset=arrivals.receiver_offset.tolist(),
                          receiver_ranges=arrivals.ranges_m.tolist(), receiver_depths=arrivals.depths_m.tolist(),
                          arrival_offset=arrivals.arrival_offset.tolist(),
                          amplitude=arrivals.amplitude.tolist(), travel_time_s=arrivals.travel_time_s.tolist(),
                          phase_radians=arrivals.phase_radians.tolist(),
                          bottom_bounces=arrivals.bottom_bounces.tolist())
        with open(args.report, "w", encoding="utf-8") as fh:
            json.dump(report, fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())
