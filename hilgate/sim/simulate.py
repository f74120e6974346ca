"""``hilgate sim``: run a scene in virtual time, as fast as the CPU allows."""

from __future__ import annotations

import json
import logging
import sys
import time
from typing import Any, TextIO

from .recorder import Recorder
from ..scene import Scene
from ..core.outputs import open_output
from ..core.scheduler import VirtualScheduler
from .apps import VirtualApps
from .world import World

log = logging.getLogger(__name__)


class ProgressBar:
    """One line on a terminal, redrawn in place; silent when stderr is not a terminal."""

    def __init__(self, total: float, stream: TextIO = sys.stderr, width: int = 30):
        self.total = total
        self.stream = stream
        self.width = width
        self.started = time.perf_counter()

    def update(self, t: float, events: int) -> None:
        fraction = min(1.0, t / self.total) if self.total > 0 else 1.0
        filled = int(fraction * self.width)
        elapsed = time.perf_counter() - self.started
        speed = t / elapsed if elapsed > 0 else 0.0
        self.stream.write(
            f"\r[{'#' * filled}{'.' * (self.width - filled)}] {fraction * 100:5.1f}%  t={t:,.1f}/{self.total:,.1f} s"
            f"  {events:,} events  {speed:,.0f}x real time "
        )
        self.stream.flush()

    def done(self) -> None:
        self.stream.write("\n")
        self.stream.flush()


class Simulation:
    """One virtual-time run of a scene; ``world`` and ``clock`` stay readable after :meth:`run`."""

    def __init__(self, scene: Scene, until: float | None = None, seed: int | None = None,
                 trace: TextIO | None = None):
        self.scene = scene
        self.seed = scene.seed if seed is None else seed
        self.until = scene.duration_s if until is None else until
        self.recorder = Recorder(trace)
        self.clock = VirtualScheduler()
        self.world = World(scene, self.clock, self.recorder, self.seed)
        self.apps = VirtualApps(self.world) if scene.apps else None

    def run(self, progress: bool = False) -> dict[str, Any]:
        """Run to the end and return the summary of DESIGN.md."""
        clock, until = self.clock, self.until
        self.world.start()
        if self.apps is not None:
            self.apps.start()
        if self.recorder.trace is not None and self.scene.trace_poses_s:
            self.world.sample_poses(self.scene.trace_poses_s, self.recorder.event)
        started = time.perf_counter()
        if progress:
            bar = ProgressBar(until)
            steps = 200
            for step in range(1, steps + 1):
                clock.run(until * step / steps)
                bar.update(clock.now(), clock.events)
            bar.done()
        else:
            clock.run(until)
        if self.apps is not None:
            self.apps.stop()
        self.wall_time = time.perf_counter() - started
        self.recorder.close()
        log.info("simulated %.1f s in %.3f s wall (%d events, %d arrivals)",
                 until, self.wall_time, clock.events, self.world.medium.arrivals)
        return self.recorder.summary(self.scene, self.seed, until, self.wall_time, self.world.modems.values())


def simulate(
    scene: Scene,
    until: float | None = None,
    seed: int | None = None,
    trace: TextIO | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Run ``scene`` for ``until`` simulated seconds (default its ``duration_s``) and return the summary."""
    return Simulation(scene, until, seed, trace).run(progress)


def write_summary(summary: dict[str, Any], path: str, group: int | None = None) -> None:
    """Into a new file (0640, ``group``) or over an earlier summary only (:mod:`hilgate.core.outputs`)."""
    with open_output(path, "summary", append=False, group=group) as handle:
        json.dump(summary, handle, indent=2)
        handle.write("\n")
