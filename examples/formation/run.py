#!/usr/bin/env python3
"""Runs UWSim-NET's third experiment end to end: the daemon, the fake BlueROV, the operator, the
leader's and the followers' applications; then says how far each follower stayed from its slot.

    python examples/formation/run.py --seconds 60 [--mac s-fama] [--out formation-out]

Writes the trace and summary, ``formation.csv`` (time, follower, error in metres) and, when
matplotlib is installed, ``formation-error.png``.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid

from hilgate.control_client import request as control_request

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "..", "..", "scenes", "paper-exp3-formation.yaml")
VIRTUAL_SCENE = os.path.join(HERE, "..", "..", "scenes", "paper-exp3-formation-virtual.yaml")  # the same applications (apps.py), in virtual time
SLOTS = {"follower1": (-1.5, 0.0, 0.0), "follower2": (0.0, -1.5, 0.0), "follower3": (-1.5, -1.5, 0.0)}
LINKS = ["buoy_ac", "leader_ac", "follower1_ac", "follower2_ac", "follower3_ac"]


def formation_errors(trace_path: str) -> list[tuple[float, str, float]]:
    poses: dict[float, dict[str, list[float]]] = {}
    with open(trace_path, encoding="utf-8") as handle:
        for line in handle:
            event = json.loads(line)
            if event.get("ev") == "pose" and event.get("position"):
                poses.setdefault(event["t"], {})[event["vehicle"]] = event["position"]
    rows = []
    for t in sorted(poses):
        snapshot = poses[t]
        if "leader" not in snapshot:
            continue
        for follower, slot in SLOTS.items():
            if follower in snapshot:
                expected = [l + s for l, s in zip(snapshot["leader"], slot)]
                rows.append((t, follower, math.dist(snapshot[follower], expected)))
    return rows


def wait_ready(notify: socket.socket, daemon: subprocess.Popen) -> bool:
    """Wait for the daemon's READY=1 (as systemd would), or for it to exit."""
    notify.settimeout(0.5)
    while daemon.poll() is None:
        try:
            if b"READY=1" in notify.recv(4096):
                return True
        except socket.timeout:
            continue
    return False


def control(runtime: str, request: dict) -> dict:
    """One request on the daemon's control socket (:mod:`hilgate.control_client`)."""
    return control_request(request, runtime, timeout=30)


def wait_attached(runtime: str, links: list[str], daemon: subprocess.Popen, timeout: float = 120.0) -> None:
    """Wait until each of ``links`` has its application attached (a client on its GLI socket).  Starting
    several Python processes takes seconds on a loaded host: a fixed sleep let the operator start its
    route before the others were there, or the route run late into the model's time."""
    deadline = time.monotonic() + timeout
    while True:
        clients = {link["id"]: link["clients"] for link in control(runtime, {"class": "STATUS"})["links"]}
        if all(clients.get(link, 0) > 0 for link in links):
            return
        if daemon.poll() is not None or time.monotonic() > deadline:
            raise SystemExit(f"the applications of {', '.join(links)} did not attach (clients: {clients})")
        time.sleep(0.05)


def stop(processes: list[subprocess.Popen]) -> None:
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    for process in processes:
        try:
            process.wait(30)  # the daemon writes the end of its trace and its summary first
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def run_virtual(args: argparse.Namespace, trace: str) -> None:
    """The same applications in virtual time: ``hilgate sim`` of the virtual scene (deterministic)."""
    scene = os.path.join(args.out, "formation-virtual.yaml")  # the route's length is the operator's parameter
    with open(VIRTUAL_SCENE, encoding="utf-8") as handle:
        text = handle.read().replace("legs: 3", f"legs: {args.legs}")
    with open(scene, "w", encoding="utf-8") as handle:
        handle.write(text.replace("plugins: [../examples/formation/apps.py]",
                                  f"plugins: [{os.path.join(HERE, 'apps.py')}]"))
    overrides = [f"links.*.mac.protocol={args.mac}"]
    if args.mac != "cs-aloha":
        overrides.append("links.*.mac.backoff_s=null")
    subprocess.run([sys.executable, "-m", "hilgate", "sim", scene, "--until", str(args.seconds),
                    "--trace", trace, "-q", *(x for o in overrides for x in ("--set", o))], check=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--mac", default="cs-aloha", choices=["cs-aloha", "s-fama", "none"])
    parser.add_argument("--legs", type=int, default=3, help="legs of the operator's route (3 m each)")
    parser.add_argument("--out", default="formation-out")
    parser.add_argument("--virtual", action="store_true",
                        help="run the applications in virtual time (hilgate sim, deterministic) instead of as "
                             "processes against the daemon with the fake BlueROV")
    parser.add_argument("--realtime-apps", action="store_true",
                        help="run apps.py's classes through `hilgate app` against `hilgate run` (the fake BlueROV "
                             "as the leader) --runs times, and print the spread beside the virtual-time run")
    parser.add_argument("--runs", type=int, default=5, help="real-time runs with --realtime-apps")
    parser.add_argument("--prefix", default=None,
                        help="prefix of this run's link ids (default: one of its own, so that several runs, and "
                             "a daemon already serving the scene, can share the machine)")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    if args.virtual:
        trace = os.path.join(args.out, f"trace-virtual-{args.mac}.jsonl")
        run_virtual(args, trace)
        return report(formation_errors(trace), args, f"virtual-{args.mac}")
    if args.realtime_apps:
        return realtime_apps_runs(args)
    trace = realtime(args, "processes", args.mac)
    return report(formation_errors(trace), args, args.mac)


def realtime(args: argparse.Namespace, kind: str, label: str) -> str:
    """One real-time run against ``hilgate run`` with the fake BlueROV as the leader; the applications
    are the process-style scripts (``kind="processes"``: operator.py, leader.py, follower.py) or the
    classes of apps.py through ``hilgate app`` (``kind="apps"``).  Returns the trace's path.

    The operator starts once the leader's and the followers' applications are attached, and the run
    lasts ``args.seconds`` from then (the model's time counts from the daemon's start: the start-up, a
    few seconds on a loaded host, comes before the operator's first waypoint, see :func:`leader_start`)."""
    runtime = tempfile.mkdtemp(prefix="hilgate-formation-")
    prefix = args.prefix if args.prefix is not None else f"f{uuid.uuid4().hex[:6]}_"
    links = {name: prefix + name for name in LINKS}
    vehicle_port, autopilot_port = free_udp_port(), free_udp_port()
    scene = os.path.join(runtime, "formation.yaml")
    with open(SCENE, encoding="utf-8") as handle:
        text = handle.read()
    text = re.sub(r"\b(" + "|".join(LINKS) + r")\b", lambda m: links[m.group(1)], text)
    text = text.replace("udpin:127.0.0.1:14560", f"udpin:127.0.0.1:{vehicle_port}")
    with open(scene, "w", encoding="utf-8") as handle:
        handle.write(text)
    trace = os.path.join(args.out, f"trace-{label}.jsonl")
    summary = os.path.join(args.out, f"summary-{label}.json")
    if os.path.exists(trace):
        os.unlink(trace)
    overrides = [f"links.*.mac.protocol={args.mac}"]
    if args.mac != "cs-aloha":
        overrides.append("links.*.mac.backoff_s=null")
    notify_path = os.path.join(runtime, "notify")
    notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    notify.bind(notify_path)
    hilgate = [sys.executable, "-m", "hilgate"]
    limit = str(args.seconds + 300)  # a bound in case this script dies: it stops them itself
    daemon = subprocess.Popen(
        [*hilgate, "run", scene, *(x for o in overrides for x in ("--set", o)), "--runtime-dir", runtime,
         "--trace", trace, "--summary", summary, "--until", limit, "--no-status-line"],
        env=dict(os.environ, NOTIFY_SOCKET=notify_path))
    apps: list[subprocess.Popen] = []
    try:
        if not wait_ready(notify, daemon):
            raise SystemExit(f"hilgate did not start (exit status {daemon.returncode})")
        python = sys.executable
        common = ["--runtime-dir", runtime]
        apps.append(subprocess.Popen([python, os.path.join(HERE, "fake_bluerov.py"), "--seconds",
                                      str(args.seconds + 5), "--to", f"udpout:127.0.0.1:{vehicle_port}",
                                      "--listen", f"udpin:127.0.0.1:{autopilot_port}"]))
        autopilot = f"udpout:127.0.0.1:{autopilot_port}"
        app = [*hilgate, "app", "--until", limit]
        classes = os.path.join(HERE, "apps.py")
        for i, (name, slot) in enumerate(SLOTS.items(), 1):
            if kind == "apps":
                command = [*app, f"{classes}:Follower", "--link", links[f"follower{i}_ac"], "--name", f"f{i}",
                           "--param", f"vehicle={name}", "--param", f"slot={list(slot)}", *common]
            else:
                command = [python, os.path.join(HERE, "follower.py"), "--link", links[f"follower{i}_ac"], "--slot",
                           *map(str, slot), *common]
            apps.append(subprocess.Popen(command))
        if kind == "apps":
            command = [*app, f"{classes}:Leader", "--link", links["leader_ac"], "--param", "vehicle=leader",
                       "--param", "period_s=1", "--param", f"autopilot={autopilot}", *common]
        else:
            command = [python, os.path.join(HERE, "leader.py"), "--link", links["leader_ac"], "--autopilot", autopilot,
                       *common]
        apps.append(subprocess.Popen(command))
        wait_attached(runtime, [links[name] for name in LINKS if name != "buoy_ac"], daemon)
        if kind == "apps":
            command = [*app, f"{classes}:Operator", "--link", links["buoy_ac"], "--param", "leader=1",
                       "--param", f"legs={args.legs}", "--param", "leg_s=12", "--param", "repeat_s=2", *common]
        else:
            command = [python, os.path.join(HERE, "operator.py"), "--link", links["buoy_ac"], "--legs", str(args.legs),
                       *common]
        apps.append(subprocess.Popen(command))
        wait_attached(runtime, [links["buoy_ac"]], daemon)
        try:
            daemon.wait(args.seconds)  # the run, from the operator's start
        except subprocess.TimeoutExpired:
            pass
        stop(apps)  # the applications first (they end their runs), then the daemon (its trace is complete)
        stop([daemon])
    finally:
        stop([*apps, daemon])
        subprocess.run([*hilgate, "queues", scene, "--unlink"], capture_output=True)  # this run's own
        notify.close()
        shutil.rmtree(runtime, ignore_errors=True)
    return trace


def leader_start(trace_path: str) -> tuple[float | None, float | None]:
    """(model time of the operator's first waypoint, of the leader's first pose 5 cm from its start):
    their difference is the leader's start delay (acoustic delivery, the applications' reaction, MAVLink
    and the autopilot; to the trace's pose period, 0.5 s)."""
    first_wp = moved = None
    start = None
    with open(trace_path, encoding="utf-8") as handle:
        for line in handle:
            event = json.loads(line)
            if first_wp is None and event.get("ev") == "enq" and event.get("link", "").endswith("buoy_ac"):
                first_wp = event["t"]
            if event.get("ev") == "pose" and event.get("vehicle") == "leader" and event.get("position"):
                if start is None:
                    start = event["position"]
                elif moved is None and math.dist(start, event["position"]) > 0.05:
                    moved = event["t"]
    return first_wp, moved


def run_figures(rows: list[tuple[float, str, float]]) -> tuple[float, float]:
    """(mean, max) follower error over the run, all followers together."""
    errors = [e for _, _, e in rows]
    return sum(errors) / len(errors), max(errors)


def realtime_apps_runs(args: argparse.Namespace) -> int:
    """``--realtime-apps --runs N``: apps.py's classes through ``hilgate app`` against ``hilgate run`` N
    times, one run at a time; prints each run and the spread (min / median / max) beside the virtual run."""
    import statistics

    per_run = []
    for run in range(1, args.runs + 1):
        trace = realtime(args, "apps", f"apps-{args.mac}-{run}")
        rows = formation_errors(trace)
        mean, largest = run_figures(rows)
        first_wp, moved = leader_start(trace)
        delay = (moved - first_wp) if first_wp is not None and moved is not None else float("nan")
        per_run.append((mean, largest, delay))
        print(f"run {run}: mean {mean:.3f} m, max {largest:.3f} m, leader start delay {delay:.1f} s "
              f"(first waypoint at {first_wp if first_wp is None else round(first_wp, 2)} s)", flush=True)
        with open(os.path.join(args.out, f"formation-apps-{args.mac}-{run}.csv"), "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["t", "follower", "error_m"])
            writer.writerows(rows)
    virtual = os.path.join(args.out, f"trace-virtual-{args.mac}.jsonl")
    run_virtual(args, virtual)
    v_mean, v_max = run_figures(formation_errors(virtual))
    v_wp, v_moved = leader_start(virtual)
    print(f"{args.mac}, {args.runs} real-time runs of {args.seconds:g} s (hilgate app against hilgate run; "
          f"min / median / max) beside the virtual-time run:")
    for i, what in enumerate(["mean follower error (m)", "max follower error (m)", "leader start delay (s)"]):
        values = [r[i] for r in per_run]
        fmt = ".1f" if i == 2 else ".3f"
        virtual_value = [v_mean, v_max, v_moved - v_wp][i]
        print(f"  {what:<26} {min(values):{fmt}} / {statistics.median(values):{fmt}} / {max(values):{fmt}}"
              f"   virtual {virtual_value:{fmt}}")
    return 0


def report(rows: list[tuple[float, str, float]], args: argparse.Namespace, label: str) -> int:
    """The follower errors: a CSV, a summary on stdout and, with matplotlib, a figure."""
    with open(os.path.join(args.out, f"formation-{label}.csv"), "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["t", "follower", "error_m"])
        writer.writerows(rows)
    settled = [r for r in rows if r[0] >= 0.75 * args.seconds]
    print(f"formation error with {label} over {args.seconds:g} s (whole run / last quarter):")
    for follower in SLOTS:
        everything = [e for _, f, e in rows if f == follower]
        errors = [e for _, f, e in settled if f == follower]
        if errors:
            print(f"  {follower}: mean {sum(everything) / len(everything):.3f} m, max {max(everything):.3f} m / "
                  f"mean {sum(errors) / len(errors):.3f} m, final {errors[-1]:.3f} m")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(9, 3.5))
        for follower in SLOTS:
            points = [(t, e) for t, f, e in rows if f == follower]
            ax.plot([t for t, _ in points], [e for _, e in points], label=follower)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("distance from the slot (m)")
        ax.set_title(f"Formation error, {label}")
        ax.legend()
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, f"formation-error-{label}.png"), dpi=110)
    except ImportError:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
