#!/usr/bin/env python3
"""How the simulator scales with the number of modems: a ring scene generator run through ``hilgate sim``.

Two geometries (``--geometry``):

- ``neighbour`` (default): N modems 100 m apart on a ring, ``range_m: [0, 250]`` (each hears two
  modems either side), every modem offers 35-byte frames to its clockwise neighbour as a Poisson
  process of 0.05 frame/s at 1 kbit/s, ``mac: none``.  The work per transmission is the same at any N,
  so the wall time per judged arrival should stay flat when the medium never visits modems beyond
  range.
- ``drifting``: the same ring, each vehicle looping around a 20 m square by its place at 0.5 m/s:
  every pair involves a moving vehicle, so the medium's moving grid does the pruning.
- ``sink``: ``ring_aloha.py``'s ring (a sink at the centre, N-1 senders on a 500 m ring, unlimited
  range), the dense ring: every transmission reaches every modem (N-1 arrivals per frame, one judged).
  Only the sink judges; the others hear each frame as interference, gathered only when a judged
  arrival or carrier sense needs it (``models/air.py``), so the cost per offered frame grows with the
  frames in the air, not with the modems that hear them.

Addresses are 1..N skipping 255 (the broadcast address): above 254 modems the scene needs wide
addresses (simulated links only).  Each run is a separate ``python -m hilgate sim`` process on a
generated scene file; ``--tree LABEL=DIR`` runs the hilgate found in DIR instead (e.g. an exported
older commit), and several trees are run alternately, N by N, repeat by repeat.  A source tree maps
``models/``, ``drivers/`` and ``scenes/`` into the package only when installed (pyproject's
package-dir), so an exported tree needs ``hilgate/models -> ../models`` (and drivers, scenes) links;
without them ``hilgate.models`` would come from the installed checkout, and the script refuses it.  Printed per run: N,
simulated seconds, transmissions, judged arrivals (rx + prop/col/mult at the addressed receivers),
the wall time of the process and of the simulation loop, and judged arrivals per wall second; then
per offered frame the loop's wall time and the process's peak memory, and for each tree how many times
its smallest N's wall time per offered frame each N costs (``--pin CPU`` runs every process on that CPU).

    python benchmarks/ring_scale.py --nodes 50 200 1000 --sim-time 3600
    python benchmarks/ring_scale.py --tree before=/tmp/old --tree after=. --nodes 50 --repeats 3
    python benchmarks/ring_scale.py --geometry sink --nodes 100 250 1000 --sim-time 720 --pin 0 --tree ...
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from placement import pinned_command  # noqa: E402

SPACING_M = 100.0
RANGE_M = 250.0


def addresses(nodes: int) -> list[int]:
    """1..N, skipping 255 (the broadcast address)."""
    result, a = [], 1
    while len(result) < nodes:
        if a != 255:
            result.append(a)
        a += 1
    return result


def ring_scene(nodes: int, sim_time: float, seed: int, geometry: str = "neighbour") -> str:
    """The scene text of one ring."""
    address = addresses(nodes)
    lines = [f"name: ring-{geometry}-{nodes}", f"seed: {seed}", f"duration_s: {sim_time}",
             "channels: {ac: {speed_mps: 1500}}", "vehicles:"]
    if geometry == "sink":
        lines.append("  v0: {pose: {static: [0, 0, 0]}}")
        for i in range(1, nodes):
            angle = 2 * math.pi * (i - 1) / (nodes - 1)
            lines.append(f"  v{i}: {{pose: {{static: [{500 * math.cos(angle)!r}, {500 * math.sin(angle)!r}, 0]}}}}")
        lines.append("links:")
        for i in range(nodes):
            lines.append(f"  m{i}: {{vehicle: v{i}, address: {address[i]}, bitrate_bps: 1000}}")
        lines.append("flows:")
        for i in range(1, nodes):
            lines.append(f"  - {{from: m{i}, to: m0, size_bytes: 35, rate_hz: 0.05, poisson: true}}")
        return "\n".join(lines) + "\n"
    radius = SPACING_M * nodes / (2 * math.pi)
    for i in range(nodes):
        angle = 2 * math.pi * i / nodes
        x, y = radius * math.cos(angle), radius * math.sin(angle)
        if geometry == "drifting":
            corners = [[round(x + dx, 3), round(y + dy, 3), 0] for dx, dy in ((10, 0), (10, 10), (0, 10), (0, 0))]
            legs = ", ".join(f"{{to: {c}, speed_mps: 0.5}}" for c in corners)
            lines.append(f"  v{i}: {{pose: {{path: {{start: [{round(x, 3)}, {round(y, 3)}, 0], legs: [{legs}], "
                         f"loop: true}}}}}}")
        else:
            lines.append(f"  v{i}: {{pose: {{static: [{x!r}, {y!r}, 0]}}}}")
    lines.append("links:")
    for i in range(nodes):
        lines.append(f"  m{i}: {{vehicle: v{i}, address: {address[i]}, bitrate_bps: 1000, range_m: [0, {RANGE_M}]}}")
    lines.append("flows:")
    for i in range(nodes):
        lines.append(f"  - {{from: m{i}, to: m{(i + 1) % nodes}, size_bytes: 35, rate_hz: 0.05, poisson: true}}")
    return "\n".join(lines) + "\n"


def tree_of(tree: str | None) -> str:
    """Where ``hilgate.models.medium`` comes from when running ``tree``: it must be inside it."""
    root = _root(tree)
    out = subprocess.run([sys.executable, "-c", "import hilgate.models.medium as m; print(m.__file__)"],
                         env=_env(root), cwd=tempfile.gettempdir(), check=True, capture_output=True, text=True)
    medium = os.path.realpath(out.stdout.strip())
    if not medium.startswith(os.path.realpath(root) + os.sep):
        sys.exit(f"ring_scale: {root}: hilgate.models comes from {medium}, not from this tree "
                 f"(link hilgate/models, hilgate/drivers and hilgate/scenes to ../models, ../drivers, ../scenes)")
    return medium


def _root(tree: str | None) -> str:
    return os.path.abspath(tree if tree is not None else os.path.join(os.path.dirname(__file__), ".."))


def _env(root: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def run_once(tree: str | None, scene_path: str, summary_path: str, pin: int | None = None) -> dict:
    env = _env(_root(tree))
    command = [sys.executable, "-m", "hilgate", "sim", scene_path, "--summary", summary_path, "-q"]
    if pin is not None:
        command = pinned_command(command, pin)
    started = time.perf_counter()
    # run from the scene's directory: ``python -m`` puts the working directory first on sys.path
    child = subprocess.Popen(command, env=env, cwd=os.path.dirname(scene_path))
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - started
    if child.returncode:
        raise subprocess.CalledProcessError(child.returncode, command)
    with open(summary_path, encoding="utf-8") as handle:
        summary = json.load(handle)
    flows = summary["flows"]
    judged = sum(f["rx_packets"] + f["lost"]["prop"] + f["lost"]["col"] + f["lost"]["mult"] for f in flows)
    return {"tx": sum(f["tx_packets"] for f in flows), "judged": judged, "offered": sum(f["offered"] for f in flows),
            "rx": sum(f["rx_packets"] for f in flows), "wall_s": wall, "sim_wall_s": summary["wall_time_s"],
            "peak_mb": usage.ru_maxrss / 1024}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nodes", type=int, nargs="*", default=[50, 200, 1000])
    parser.add_argument("--sim-time", type=float, default=3600.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--geometry", choices=("neighbour", "drifting", "sink"), default="neighbour")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--pin", type=int, metavar="CPU", help="run every hilgate process on this CPU")
    parser.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR",
                        help="run the hilgate in DIR (repeatable: the trees are run alternately)")
    args = parser.parse_args()
    trees = [tuple(t.split("=", 1)) for t in args.tree] or [("this", None)]
    print(f"geometry {args.geometry}, {args.sim_time:g} simulated s, seed {args.seed}, repeats {args.repeats}, "
          f"{'pinned to CPU ' + str(args.pin) if args.pin is not None else 'not pinned'}")
    for label, tree in trees:
        print(f"{label}: {tree_of(tree)}")
    print(f"{'tree':>8} {'N':>5} {'tx':>8} {'judged':>8} {'rx':>8} {'wall s':>8} {'sim s':>8} "
          f"{'judged/s':>9} {'us/judged':>9} {'offered':>8} {'us/offered':>10} {'peak MB':>8}")
    per_frame: dict[str, dict[int, list[float]]] = {label: {} for label, _ in trees}
    with tempfile.TemporaryDirectory(prefix="ring_scale-") as tmp:
        for n in args.nodes:
            scene_path = os.path.join(tmp, f"ring-{n}.yaml")
            with open(scene_path, "w", encoding="utf-8") as handle:
                handle.write(ring_scene(n, args.sim_time, args.seed, args.geometry))
            results: dict[str, list[dict]] = {label: [] for label, _ in trees}
            for _ in range(args.repeats):
                for label, tree in trees:  # alternating: each repeat runs every tree once
                    try:
                        r = run_once(tree, scene_path, os.path.join(tmp, "summary.json"), args.pin)
                    except subprocess.CalledProcessError as exc:
                        print(f"{label:>8} {n:>5} not run: hilgate sim exited {exc.returncode} (above)", flush=True)
                        continue
                    results[label].append(r)
                    us_offered = 1e6 * r["sim_wall_s"] / r["offered"]
                    per_frame[label].setdefault(n, []).append(us_offered)
                    print(f"{label:>8} {n:>5} {r['tx']:>8} {r['judged']:>8} {r['rx']:>8} {r['wall_s']:>8.2f} "
                          f"{r['sim_wall_s']:>8.2f} {r['judged'] / r['sim_wall_s']:>9.0f} "
                          f"{1e6 * r['sim_wall_s'] / r['judged']:>9.1f} {r['offered']:>8} {us_offered:>10.1f} "
                          f"{r['peak_mb']:>8.1f}", flush=True)
            if len(trees) > 1 and args.repeats > 1:
                for label, runs in results.items():
                    if not runs:
                        continue
                    walls = sorted(r["sim_wall_s"] for r in runs)
                    print(f"{label:>8} {n:>5} sim wall min/median/max {walls[0]:.2f}/{statistics.median(walls):.2f}"
                          f"/{walls[-1]:.2f} s")
    for label, by_n in per_frame.items():
        if len(by_n) < 2:
            continue
        smallest = min(by_n)
        base = statistics.median(by_n[smallest])
        ratios = ", ".join(f"N = {n}: {statistics.median(v) / base:.1f}x" for n, v in sorted(by_n.items()) if n != smallest)
        print(f"{label:>8}: wall per offered frame against N = {smallest} ({base:.1f} us): {ratios}")


if __name__ == "__main__":
    main()
