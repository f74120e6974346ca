"""Reloading the daemon's scene (SIGHUP, ``systemctl reload``, a control RELOAD) while it keeps delivering.

The file is loaded and validated in a worker process (:mod:`hilgate.scene.worker`) while the loop keeps
delivering; a valid scene is applied on the loop.  Every outcome is answered to the asker, logged in one
line and followed by READY=1.  A reload asked while one runs is done once more after it, so the last
version of the file always wins.  Apart from the daemon because it is a small state machine of its own
(one job running, one more asked for, who waits for which)."""

from __future__ import annotations

import logging
import time
from typing import Any, Callable

from ..core.notify import notify
from ..scene import Scene, SceneError
from ..scene.links import require_narrow_addresses
from ..scene.worker import SceneJob, request_for

__all__ = ["Reloader"]

log = logging.getLogger(__name__)

Reply = Callable[[bool, str], Any]


class Reloader:
    """``apply(scene)`` applies a loaded scene on the loop (raising SceneError: refused untouched; any
    other exception: applied in part); ``count()`` says how many links run, for the log."""

    def __init__(self, scheduler: Any, options: Any, prepare: Callable[[Scene], None],
                 apply: Callable[[Scene], None], count: Callable[[], int]):
        self.scheduler = scheduler
        self.options = options
        self.prepare = prepare
        self.apply = apply
        self.count = count
        self.scene: Scene | None = None  # the running scene's name, for systemd's status
        self.job: SceneJob | None = None
        self.again = False
        self.waiting: list[Reply] = []
        self.next: list[Reply] = []

    def reload(self, reply: Reply | None = None) -> None:
        if self.job is not None:
            self.again = True
            if reply is not None:
                self.next.append(reply)
            return
        if reply is not None:
            self.waiting.append(reply)
        notify("RELOADING=1", f"MONOTONIC_USEC={time.monotonic_ns() // 1000}", "STATUS=reloading")
        log.info("reloading %s", self.options.scene_path)
        try:
            request = request_for(self.options.scene_path, list(self.options.overrides),
                                  plugins=list(self.options.plugins), preset_dirs=list(self.options.preset_dirs))
            self.job = SceneJob(self.scheduler, request, self._loaded)
        except Exception as exc:  # cannot even start the worker (out of processes, memory…)
            self._finished(False, f"cannot start the scene loader: {type(exc).__name__}: {exc}")

    def _loaded(self, scene: Scene | None, error: str | None) -> None:
        self.job = None
        if scene is None:
            self._finished(False, error or "unknown error")
            return
        try:
            require_narrow_addresses(scene.links.values())
            self.prepare(scene)
        except SceneError as exc:
            self._finished(False, str(exc))
            return
        try:
            self.apply(scene)
            self.scene = scene
        except Exception as exc:  # e.g. a new link's port or queue cannot be opened
            log.debug("reload failed while applying", exc_info=True)
            self._finished(False, f"applying the new scene failed (it may be applied in part): "
                                  f"{type(exc).__name__}: {exc}")
            return
        self._finished(True, "")

    def _finished(self, ok: bool, error: str) -> None:
        if ok:
            log.info("reloaded %s: %d links", self.options.scene_path, self.count())
            notify("READY=1", f"STATUS=running {self.scene.name!r}: {self.count()} links")
        else:
            error = " ".join(error.split())
            log.error("reload refused, the running scene stays: %s", error)
            notify("READY=1", f"STATUS=reload refused: {error}"[:1000])
        waiting, self.waiting = self.waiting, []
        for reply in waiting:
            try:
                reply(ok, error)
            except Exception:
                log.exception("answering a reload request failed")
        if self.again:
            self.again = False
            self.waiting, self.next = self.next, []
            self.reload()

    def cancel(self) -> None:
        if self.job is not None:
            self.job.cancel()
