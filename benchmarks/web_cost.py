#!/usr/bin/env python3
"""What the web view costs the daemon: its CPU at 100 frames/s without ``--web``, with ``--web`` and no page,
and with a page connected.

The daemon runs a scene whose flows put 100 frames a second on air (four vehicles 100-600 m apart, four
links, 32-byte frames at 25 a second each), in real time.  Three configurations alternate, ``--repeats``
times, each a fresh daemon: (1) no web door, the anchor; (2) ``--web`` with no page; (3) ``--web`` with a
page, here a WebSocket client in this process that proves the token and reads every picture as a browser
would (a browser's own drawing costs the browser, not the daemon).  Each is measured over ``--seconds``
of wall clock after a warm-up: the daemon's CPU time (every thread, from /proc) over that time, as a
percentage of one core, the frames it put on air, and for (3) the pictures and bytes the page got.
Target: a page costs under 5 % of a core.

    python benchmarks/web_cost.py [--seconds 20] [--repeats 3]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid

from hilgate.gli.token import proof, read_token

WARM_UP_S = 3.0
TICKS = os.sysconf("SC_CLK_TCK")


def scene(prefix: str) -> str:
    links = "\n".join(f"  {prefix}{i}: {{vehicle: v{i}, address: {i + 1}, bitrate_bps: 100000, gli: [socket]}}"
                      for i in range(4))
    flows = "\n".join(f"  - {{from: {prefix}{i}, to: {prefix}{(i + 1) % 4}, size_bytes: 32, interval_s: 0.04, "
                      f"poisson: true}}" for i in range(4))
    return f"""\
name: web-cost
seed: 3
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  v0: {{pose: {{static: [0, 0, 5]}}}}
  v1: {{pose: {{static: [100, 0, 5]}}}}
  v2: {{pose: {{static: [300, 400, 20]}}}}
  v3: {{pose: {{path: {{start: [600, 0, 10], legs: [{{to: [600, 300, 10], speed_mps: 2}}, {{to: [600, 0, 10], speed_mps: 2}}], loop: true}}}}}}
links:
{links}
flows:
{flows}
"""


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as handle:
        fields = handle.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime + stime, every thread


def control(runtime: str, request: dict) -> dict:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(10)
        sock.connect(os.path.join(runtime, "control.sock"))
        reader = sock.makefile("r")
        reader.readline()
        sock.sendall((json.dumps(request) + "\n").encode())
        return json.loads(reader.readline())


class Page(threading.Thread):
    """A page: proves the token, then reads every message; counts pictures and bytes."""

    def __init__(self, url: str, token: bytes):
        super().__init__(daemon=True)
        self.url, self.token = url, token
        self.pictures = self.bytes = 0
        self.welcome = threading.Event()
        self.stop = False

    def run(self) -> None:
        asyncio.run(self._read())

    async def _read(self) -> None:
        from tornado.websocket import websocket_connect

        connection = await websocket_connect(self.url.replace("http://", "ws://") + "ws")
        hello = json.loads(await connection.read_message())
        await connection.write_message(json.dumps({"class": "AUTH", "proof": proof(self.token, bytes.fromhex(hello["nonce"]))}))
        while not self.stop:
            text = await connection.read_message()
            if text is None:
                return
            kind = json.loads(text).get("class")
            if kind == "WELCOME":
                self.welcome.set()
            elif kind == "STATE":
                self.pictures += 1
                self.bytes += len(text)
        connection.close()


def measure(config: str, seconds: float) -> dict:
    prefix = f"wc{uuid.uuid4().hex[:6]}"
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "scene.yaml")
        with open(path, "w") as handle:
            handle.write(scene(prefix))
        runtime = os.path.join(tmp, "rt")
        args = [sys.executable, "-m", "hilgate", "run", path, "--runtime-dir", runtime, "--no-status-line"]
        if config != "no web door":
            args += ["--web", "0"]
        daemon = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        page = None
        try:
            deadline = time.monotonic() + 60
            while True:
                try:
                    status = control(runtime, {"class": "STATUS"})
                    break
                except OSError:
                    if time.monotonic() > deadline or daemon.poll() is not None:
                        raise RuntimeError(f"the daemon did not start ({config})")
                    time.sleep(0.1)
            if config == "a page connected":
                web = status["web"]
                page = Page(web["url"], read_token(web["token_file"]))
                page.start()
                if not page.welcome.wait(60):
                    raise RuntimeError("the page was not welcomed")
            time.sleep(WARM_UP_S)
            tx0 = sum(link["tx_packets"] for link in control(runtime, {"class": "STATUS"})["links"])
            cpu0, wall0 = cpu_seconds(daemon.pid), time.monotonic()
            pictures0, bytes0 = (page.pictures, page.bytes) if page else (0, 0)
            time.sleep(seconds)
            cpu1, wall1 = cpu_seconds(daemon.pid), time.monotonic()
            pictures1, bytes1 = (page.pictures, page.bytes) if page else (0, 0)
            tx1 = sum(link["tx_packets"] for link in control(runtime, {"class": "STATUS"})["links"])
        finally:
            if page is not None:
                page.stop = True
            daemon.send_signal(signal.SIGTERM)
            daemon.wait(30)
        wall = wall1 - wall0
        return {"cpu": 100 * (cpu1 - cpu0) / wall, "frames_s": (tx1 - tx0) / wall,
                "pictures_s": (pictures1 - pictures0) / wall, "kb_s": (bytes1 - bytes0) / wall / 1000}


def spread(values: list[float]) -> str:
    return f"{min(values):.2f} / {statistics.median(values):.2f} / {max(values):.2f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    configs = ["no web door", "--web, no page", "a page connected"]
    results: dict[str, list[dict]] = {config: [] for config in configs}
    for _ in range(args.repeats):
        for config in configs:
            results[config].append(measure(config, args.seconds))
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"Web view cost: a daemon at ~100 frames/s (4 links, 32 B), {args.seconds:g} s per measure after "
          f"{WARM_UP_S:g} s, {args.repeats} repeat(s), configurations alternating; {os.cpu_count()} cores, "
          f"load average {load} at the end.  CPU: % of one core, min / median / max")
    for config in configs:
        rows = results[config]
        line = (f"  {config:<18} CPU {spread([r['cpu'] for r in rows])} %   "
                f"frames on air {statistics.median(r['frames_s'] for r in rows):.0f}/s")
        if config == "a page connected":
            line += (f"   pictures {statistics.median(r['pictures_s'] for r in rows):.1f}/s, "
                     f"{statistics.median(r['kb_s'] for r in rows):.1f} kB/s")
        print(line)
    anchor = [r["cpu"] for r in results["no web door"]]
    for config in configs[1:]:
        added = [r["cpu"] - a for r, a in zip(results[config], anchor)]
        print(f"  {config} adds {spread(added)} % of a core (each repeat against the anchor of its round)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
