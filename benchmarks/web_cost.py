#!/usr/bin/env python3
"""What the web view costs the daemon: its CPU at 100 frames/s without ``--web``, with ``--web`` and no page,
and with one and with three pages connected.

The daemon runs a scene whose flows put 100 frames a second on air (four vehicles 100-600 m apart, four
links, 32-byte frames at 25 a second each), in real time.  Three configurations alternate, ``--repeats``
times, each a fresh daemon: (1) no web door, the anchor; (2) ``--web`` with no page; (3) ``--web`` with a
page, here a WebSocket client in this process that proves the token and reads every picture as a browser
would (a browser's own drawing costs the browser, not the daemon); (4) three such pages (an operator, a
colleague, a projector: the picture is built once and encoded once, then written three times).  Each is measured over ``--seconds``
of wall clock after a warm-up: the daemon's CPU time (every thread, from /proc) over that time, as a
percentage of one core, the frames it put on air, and for (3) the pictures and bytes the page got.
Target: a page costs under 5 % of a core.

    python benchmarks/web_cost.py [--seconds 20] [--repeats 3] [--warm-up 3]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import sys
import tempfile
import threading
import time
import uuid

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from daemon_harness import Daemon, cpu_seconds  # noqa: E402

from hilgate.gli.token import proof, read_token  # noqa: E402

TICKS = os.sysconf("SC_CLK_TCK")
PAGES = {"a page connected": 1, "3 pages connected": 3}


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


def measure(config: str, seconds: float, warm_up: float) -> dict:
    prefix = f"wc{uuid.uuid4().hex[:6]}"
    with tempfile.TemporaryDirectory() as tmp:
        daemon = Daemon(scene(prefix), args=() if config == "no web door" else ("--web", "0"), directory=tmp)
        pages: list[Page] = []
        try:
            status = daemon.status()
            for _ in range(PAGES.get(config, 0)):
                web = status["web"]
                page = Page(web["url"], read_token(web["token_file"]))
                page.start()
                pages.append(page)
                if not page.welcome.wait(60):
                    raise RuntimeError("the page was not welcomed")
            time.sleep(warm_up)
            tx0 = sum(link["tx_packets"] for link in daemon.status()["links"])
            cpu0, wall0 = cpu_seconds(daemon.process.pid), time.monotonic()
            page = pages[0] if pages else None
            pictures0, bytes0 = (page.pictures, page.bytes) if page else (0, 0)
            time.sleep(seconds)
            cpu1, wall1 = cpu_seconds(daemon.process.pid), time.monotonic()
            pictures1, bytes1 = (page.pictures, page.bytes) if page else (0, 0)
            tx1 = sum(link["tx_packets"] for link in daemon.status()["links"])
        finally:
            for page in pages:
                page.stop = True
            daemon.close()
        wall = wall1 - wall0
        return {"cpu": 100 * (cpu1 - cpu0) / wall, "frames_s": (tx1 - tx0) / wall,
                "pictures_s": (pictures1 - pictures0) / wall, "kb_s": (bytes1 - bytes0) / wall / 1000}


def spread(values: list[float]) -> str:
    return f"{min(values):.2f} / {statistics.median(values):.2f} / {max(values):.2f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--warm-up", type=float, default=3.0, help="seconds of a fresh daemon not measured")
    args = parser.parse_args()
    configs = ["no web door", "--web, no page", "a page connected", "3 pages connected"]
    results: dict[str, list[dict]] = {config: [] for config in configs}
    for _ in range(args.repeats):
        for config in configs:
            results[config].append(measure(config, args.seconds, args.warm_up))
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"Web view cost: a daemon at ~100 frames/s (4 links, 32 B), {args.seconds:g} s per measure after "
          f"{args.warm_up:g} s, {args.repeats} repeat(s), configurations alternating; {os.cpu_count()} cores, "
          f"load average {load} at the end.  CPU: % of one core, min / median / max")
    for config in configs:
        rows = results[config]
        line = (f"  {config:<18} CPU {spread([r['cpu'] for r in rows])} %   "
                f"frames on air {statistics.median(r['frames_s'] for r in rows):.0f}/s")
        if config in PAGES:
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
