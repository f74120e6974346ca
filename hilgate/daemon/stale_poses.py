"""Vehicles whose pose source has gone quiet: one verdict for ``hilgate status``, the live view and
the log.

A live vehicle's pose (MAVLink, a camera, ROS 2, another host's) that is older than the scene's
``stale_after_s`` is *stale*, and so is one that never came once the daemon has run that long: the
medium then holds or drops it (``stale: hold|drop``), and the operator must know that the model's
distances rest on an old or invented position.  Scripted and application-steered vehicles never go
stale.  :class:`StaleWatch` is one wall-clock timer on the loop that logs each change of verdict once
(a warning when a vehicle goes stale, a line when it is fresh again), so a journal shows when a
tether was cut even if nobody watched the page.
"""

from __future__ import annotations

import logging
from typing import Any

log = logging.getLogger(__name__)

CHECK_S = 0.5
"""Wall-clock seconds between two looks (the status line's pace)."""


def staleness(pose: Any, spec: Any, now: float) -> str | None:
    """``None`` (fresh, or a computed pose), ``"stale"`` (older than ``stale_after_s``) or ``"never"``
    (nothing heard though the daemon has run ``stale_after_s``) for the vehicle ``spec`` at model time
    ``now``."""
    if spec is None or (spec.pose.kind != "live" and not spec.host):
        return None
    age = pose.age(now)
    if age is None:
        return "never" if now > spec.stale_after_s else None
    return "stale" if age > spec.stale_after_s else None


class StaleWatch:
    """Logs each vehicle's pose going stale and coming back, from the loop, every ``CHECK_S``."""

    def __init__(self, scheduler: Any, router: Any):
        self.scheduler = scheduler
        self.router = router
        self.verdicts: dict[str, str | None] = {}

    def start(self) -> None:
        self.scheduler.after_wall(CHECK_S, self._tick)

    def _tick(self) -> None:
        self.scheduler.after_wall(CHECK_S, self._tick)
        try:
            self.check()
        except Exception:  # the watch must never cost the loop
            log.exception("the stale-pose watch failed")

    def check(self) -> None:
        router = self.router
        if router.world is None or router.scene is None:
            return
        now = self.scheduler.now()
        specs = router.scene.vehicles
        for name, pose in router.world.poses.items():
            spec = specs.get(name)
            verdict = staleness(pose, spec, now)
            before = self.verdicts.get(name)
            self.verdicts[name] = verdict
            if verdict == before:
                continue
            source = spec.pose.source_name if spec is not None else "?"
            if spec is not None and spec.host:
                source = f"host {spec.host}"
            if verdict == "stale":
                log.warning("vehicle %s: pose stale: nothing from %s for %.1f s (stale_after_s %g; %s)", name,
                            source, pose.age(now), spec.stale_after_s, _policy(spec))
            elif verdict == "never":
                log.warning("vehicle %s: no pose from %s after %.1f s (stale_after_s %g; %s)", name, source, now,
                            spec.stale_after_s, _policy(spec))
            elif before is not None:
                log.info("vehicle %s: pose fresh again from %s", name, source)


def _policy(spec: Any) -> str:
    if spec.stale == "drop":
        return "dropped: its modems hear nothing and are heard by nobody"
    return "held at its last position"
