#!/usr/bin/env python3
"""``make bench``: run every benchmark once, one after the other, and keep what they printed.

Each benchmark's standard output is shown as it comes and written to ``--out`` (default
``bench.out``) under a header line ``== <command line> ==`` and a line with the load average when it
started (other work on the machine moves every figure), after a first block saying when, on which host
(cores, the CPUs this run may use, load average) and with which peers.  ``benchmarks/readme_bench.py`` turns that file into
docs/performance.md, so no figure there is typed by hand.  A benchmark that fails stops
the run (exit 1) and the file is left incomplete on purpose.

    python benchmarks/run_all.py [--ns3-python PATH] [--out bench.out]
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def benchmarks(ns3_python: str | None) -> list[list[str]]:
    ns3 = ["--ns3-python", ns3_python] if ns3_python else []
    return [
        ["benchmarks/ring_aloha.py", "--drop-when-busy", *ns3],
        ["benchmarks/realtime_lateness.py", *ns3],
        ["benchmarks/realtime_load.py", *ns3],
        ["benchmarks/gli_roundtrip.py"],
        ["benchmarks/pass_cost.py", "20000"],
        ["benchmarks/multihost.py"],
        ["benchmarks/hosts_scale.py"],
        ["benchmarks/many_links.py"],
        ["benchmarks/ring_scale.py", "--nodes", "50", "200", "1000"],
        # the dense ring (every modem hears every other): the cost per offered frame as N grows tenfold
        ["benchmarks/ring_scale.py", "--geometry", "sink", "--nodes", "100", "250", "1000", "--sim-time", "720",
         "--pin", str(min(os.sched_getaffinity(0)))],
        ["benchmarks/ring_aloha.py", "--drop-when-busy", "--nodes", "250", "--sim-time", "3600", *ns3],
        ["benchmarks/ring_aloha.py", "--nodes", "1000", "--sim-time", "3600", "--repeats", "1"],
        ["benchmarks/aruco.py"],
        ["benchmarks/web_cost.py"],
        ["benchmarks/floods.py"],
        ["benchmarks/web_redraws.py"],
        ["benchmarks/bellhop_lookup.py"],
    ]


def shown_path(path: str | None) -> str | None:
    """``path`` relative to the repository when it is inside (.venv-ns3/bin/python): no one's home folder in the docs."""
    if not path:
        return path
    relative = os.path.relpath(os.path.abspath(path), os.path.dirname(HERE))
    return path if relative.startswith("..") else relative


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--ns3-python", default=os.environ.get("NS3_PYTHON") or None,
                        help="a Python with the ns3 wheel (also $NS3_PYTHON); without it ns-3 is not run")
    parser.add_argument("--out", default="bench.out")
    args = parser.parse_args()
    os.chdir(os.path.dirname(HERE))
    with open(args.out, "w") as out:
        started = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
        cpus = ",".join(str(c) for c in sorted(os.sched_getaffinity(0)))
        out.write(f"# make bench, {started}: {os.cpu_count()} cores (this run may use CPUs {cpus}), load average {load} at the start, "
                  f"Python {platform.python_version()}, {platform.machine()}; "
                  f"ns-3: {shown_path(args.ns3_python) or 'not installed (no --ns3-python / NS3_PYTHON)'}\n")
        for argv in benchmarks(args.ns3_python):
            shown = " ".join(argv[:1] + [a if a != args.ns3_python else "NS3_PYTHON" for a in argv[1:]])
            header = f"== {shown} =="
            load = "(load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg()) + " as it started)"
            print(header, load, sep="\n", flush=True)
            out.write(header + "\n" + load + "\n")
            out.flush()
            process = subprocess.Popen([sys.executable, *argv], stdout=subprocess.PIPE, text=True, bufsize=1)
            for line in process.stdout:
                sys.stdout.write(line)
                sys.stdout.flush()
                out.write(line)
                out.flush()
            if process.wait() != 0:
                print(f"{argv[0]} failed (exit {process.returncode}); {args.out} is incomplete", file=sys.stderr)
                return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
