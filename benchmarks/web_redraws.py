#!/usr/bin/env python3
"""How fast the operator's page redraws in Chromium, where people look: the shipped demo live, the
paper's scenes replayed at 1× and 100×, and a large scene of 50 vehicles and 100 links live.

Each case opens the page in Debian's headless chromium (as the browser tests do, at 1280×800), waits
``--warm-up`` seconds, then counts the page's redraws (``window.hilgateView.drawn``: one per animation
frame that drew the chart) over ``--seconds`` of wall clock, ``--repeats`` times.  Chromium caps
animation frames at 60 a second.  Aim (issue 41): 30 redraws/s on the demo, 20 on the large scene.
A redraw is every layer the page keeps up to date (frames in flight each time; the grid, rings,
trails and vehicles when a picture came or the view moved).  The figures are the page's, on this
machine, at the load it had; the load average is printed with them.

    python benchmarks/web_redraws.py [--seconds 10] [--repeats 3] [--warm-up 4] [--case demo ...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(REPO, "tests"))
from daemon_harness import Daemon  # noqa: E402

import yaml  # noqa: E402


def sockets_only(text: str) -> str:
    """A scene on the GLI's sockets only: the benchmark needs no POSIX queue (the user's budget is shared)."""
    data = yaml.safe_load(text)
    for link in data["links"].values():
        link["gli"] = ["socket"]
    return yaml.safe_dump(data, sort_keys=False)


def large_scene(vehicles: int = 50) -> str:
    """50 vehicles on a 2 km square, half of them moving, each with an acoustic and an RF modem (100
    links), and 40 flows: a fleet's worth of traffic."""
    lines = ["name: fleet", "seed: 5", "channels: {ac: {speed_mps: 1500}, rf: {speed_mps: 2.25e7}}", "vehicles:"]
    for i in range(vehicles):
        x, y = (i % 10) * 200.0, (i // 10) * 400.0
        if i % 2:
            lines.append(f"  v{i}: {{pose: {{path: {{start: [{x}, {y}, 10], legs: [{{to: [{x + 150}, {y + 100}, 20], "
                         f"speed_mps: 2}}, {{to: [{x}, {y}, 10], speed_mps: 2}}], loop: true}}}}}}")
        else:
            lines.append(f"  v{i}: {{pose: {{static: [{x}, {y}, {5 + i % 7}]}}}}")
    lines.append("links:")
    for i in range(vehicles):
        lines.append(f"  ac{i}: {{vehicle: v{i}, address: {i + 1}, channel: ac, bitrate_bps: 2000, range_m: [0, 1500], "
                     f"error: {{unit: packet, expr: 'd / 3000'}}, gli: [socket]}}")
        lines.append(f"  rf{i}: {{vehicle: v{i}, address: {i + 1}, channel: rf, bitrate_bps: 100000, range_m: [0, 300], "
                     f"gli: [socket]}}")
    lines.append("flows:")
    for i in range(0, vehicles, 2):
        lines.append(f"  - {{from: ac{i}, to: ac{(i + 7) % vehicles}, size_bytes: 32, interval_s: 4, poisson: true}}")
        lines.append(f"  - {{from: rf{i}, to: rf{(i + 1) % vehicles}, size_bytes: 20, interval_s: 0.5}}")
    return "\n".join(lines) + "\n"


def measure_page(url: str, seconds: float, warm_up: float, play_speed: float | None = None) -> float:
    from browser_kit import Browser

    browser = Browser()
    try:
        browser.viewport(1280, 800)
        browser.open(url)
        browser.wait("v.authed && v.scene && v.state", "the page", timeout=120)
        if play_speed is not None:
            browser.js(f"window.hilgateView.send({{class: 'SPEED', speed: {play_speed}}});"
                       "window.hilgateView.send({class: 'PLAY'});")
            browser.wait("v.state.playing || v.state.t > v.state.start", "the player", timeout=60)  # (at 100× it may be over)
        def again() -> None:  # a trace shorter than the measure at this speed plays again from its start
            if play_speed is not None and not browser.view("v.state.playing"):
                browser.js("window.hilgateView.seekTo(0); window.hilgateView.send({class: 'PLAY'});")

        end = time.monotonic() + warm_up
        while time.monotonic() < end:
            again()
            time.sleep(0.1)
        d0, t0 = browser.view("v.drawn"), time.monotonic()
        while time.monotonic() < t0 + seconds:
            again()
            time.sleep(0.1)
        d1, t1 = browser.view("v.drawn"), time.monotonic()
        return (d1 - d0) / (t1 - t0)
    finally:
        browser.close()


def live(scene_text: str, seconds: float, warm_up: float) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        daemon = Daemon(scene_text, args=("--web", "0"), directory=tmp)
        try:
            url = subprocess.run([sys.executable, "-m", "hilgate", "view", "--runtime-dir", daemon.runtime],
                                 capture_output=True, text=True, check=True).stdout.strip()
            return measure_page(url, seconds, warm_up)
        finally:
            daemon.close()


def replay(scene_path: str, speed: float, seconds: float, warm_up: float) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        trace = os.path.join(tmp, "trace.jsonl")
        subprocess.run([sys.executable, "-m", "hilgate", "sim", scene_path, "--trace", trace, "-q"], check=True)
        viewer = subprocess.Popen([sys.executable, "-m", "hilgate", "view", trace, "--scene", scene_path],
                                  stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        try:
            line = viewer.stdout.readline()
            return measure_page(line.split(" at ", 1)[1].split(" ")[0], seconds, warm_up, play_speed=speed)
        finally:
            viewer.terminate()
            viewer.wait(30)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--warm-up", type=float, default=4.0)
    parser.add_argument("--case", action="append", help="demo, exp1-acoustic-1x, exp1-acoustic-100x, exp1-rf-1x, "
                                                        "exp1-rf-100x, large (default: all)")
    args = parser.parse_args()
    with open(os.path.join(REPO, "scenes", "demo.yaml")) as handle:
        demo = sockets_only(handle.read())
    cases = {
        "demo": lambda: live(demo, args.seconds, args.warm_up),
        "exp1-acoustic-1x": lambda: replay(os.path.join(REPO, "scenes", "paper-exp1-acoustic.yaml"), 1, args.seconds, args.warm_up),
        "exp1-acoustic-100x": lambda: replay(os.path.join(REPO, "scenes", "paper-exp1-acoustic.yaml"), 100, args.seconds, args.warm_up),
        "exp1-rf-1x": lambda: replay(os.path.join(REPO, "scenes", "paper-exp1-rf.yaml"), 1, args.seconds, args.warm_up),
        "exp1-rf-100x": lambda: replay(os.path.join(REPO, "scenes", "paper-exp1-rf.yaml"), 100, args.seconds, args.warm_up),
        "large": lambda: live(large_scene(), args.seconds, args.warm_up),
    }
    chosen = args.case or list(cases)
    started = time.strftime("%Y-%m-%d %H:%M")
    results = {}
    for name in chosen:
        results[name] = [cases[name]() for _ in range(args.repeats)]
        print(f"  {name:<20} {' '.join(f'{r:5.1f}' for r in results[name])}   median {statistics.median(results[name]):5.1f} redraws/s",
              flush=True)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"Page redraws in headless Chromium at 1280×800, {started}: {args.seconds:g} s per measure after "
          f"{args.warm_up:g} s (a replay that ends plays again from its start), {args.repeats} repeat(s); "
          f"{os.cpu_count()} cores, load average {load} at the end.")
    for name in chosen:
        print(f"  {name:<20} median {statistics.median(results[name]):5.1f}, min {min(results[name]):5.1f} redraws/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
