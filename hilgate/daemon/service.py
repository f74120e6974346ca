"""``hilgate run``: the daemon.  Loads the scene, opens every endpoint, tells systemd it is ready,
runs the model in real time, reloads on SIGHUP and stops cleanly (trace complete) on SIGTERM/SIGINT."""

from __future__ import annotations

import datetime
import gc
import logging
import os
import signal
import sys
import time
import uuid
from typing import Any, Callable

from .. import __version__
from .access import (lock_directory, prepare_lock_directory, prepare_private_dir, raise_descriptor_limit,
                     resolve_group)
from .control import ControlServer
from .doors import DoorSetting, open_doors
from ..gli.queues import forget_created, raise_queue_budget, unlink_created
from ..gli.sockets import ClientLimits, tcp_listener
from ..gli.token import TOKEN_FILE, TokenCheck, load_or_create
from .live_sources import LiveSources
from .network_setup import host_of
from .options import DaemonOptions, parse_tcp
from .reload import Reloader
from .ros2_bridge import Ros2Bridge
from ..core.priority import Scheduling, current, raise_priority
from ..core.realtime import RealtimeScheduler
from ..sim.recorder import Recorder
from .router import Router
from .stale_poses import StaleWatch
from .start_line import endpoint_list, link_list, links_phrase
from .network import Network
from ..scene import Scene, load_scene
from ..scene.links import require_narrow_addresses
from ..scene.view import scene_view, view_hash
from ..core.notify import notify, watchdog_interval
from ..core.outputs import OutputError, open_output, output_problem
from ..sim.simulate import write_summary

__all__ = ["Daemon", "DaemonOptions", "parse_tcp"]

log = logging.getLogger(__name__)


class Daemon:
    """``hilgate run``: its options (:class:`~hilgate.daemon.options.DaemonOptions`, given as that class's
    fields), what :meth:`run` opens (the doors from the door table, the pose sources from theirs), and
    what it answers (status, reload, stop)."""

    def __init__(self, scene_path: str, *args: Any, **kwargs: Any):
        self.options = options = DaemonOptions(scene_path, *args, **kwargs)
        self.scene_path = options.scene_path
        self.scheduling = Scheduling()  # what the loop thread runs at (status): set as the loop starts
        self.web_server: Any = None
        self.web_feed: Any = None
        self.network: Network | None = None
        self.scene: Scene | None = None
        self.trace = None
        # made by run(); shutdown() closes what a failed start got as far as making
        self.group: int | None = None
        self.scheduler: RealtimeScheduler | None = None
        self.router: Router | None = None
        self.live: LiveSources | None = None
        self.control: ControlServer | None = None
        self.tcp_listener: Any = None
        self.ros2: Ros2Bridge | None = None
        self.reloader: Reloader | None = None
        self.stopping = False
        self.started = time.monotonic()

    def run(self) -> int:
        options = self.options
        scene = load_scene(self.scene_path, list(options.overrides), plugins=list(options.plugins),
                           preset_dirs=list(options.preset_dirs))  # a bad scene never half-starts
        require_narrow_addresses(scene.links.values())
        self.scene = scene
        host = host_of(options, scene)
        token_check = self._prepare_files()
        scheduler = self._open_trace(scene)
        lock_dir = lock_directory(options.runtime_dir)
        prepare_lock_directory(lock_dir)
        self.router = Router(scheduler, self.recorder, max_link_clients=options.max_link_clients, host=host,
                             lock_dir=lock_dir)
        self.clients = ClientLimits(options.max_clients, options.max_link_clients, auth_timeout_s=options.auth_timeout_s)
        try:
            self._open(scene, host, token_check)
        except BaseException:
            removed = unlink_created()  # it never said READY: its queues would only cost the user's budget
            if removed:
                log.info("start-up failed: removed the %d queues this daemon had created", len(removed))
            self.shutdown()
            raise
        forget_created()  # from now on applications may hold them: never unlinked by the daemon
        if self.network is not None:
            self._join_clock(scene, host)
        self._take_priority()
        try:
            notify("READY=1", f"STATUS=running {scene.name!r}: {len(self.router.links)} links",
                   f"MAINPID={os.getpid()}")
            scheduler.run(options.until if options.until is not None else float("inf"))
        finally:
            self.shutdown()
        return 0

    def _prepare_files(self) -> TokenCheck | None:
        """The runtime folders, the token and the web port, refused before anything opens; the limits raised."""
        options = self.options
        group = self.group = resolve_group(options.group)
        prepare_private_dir(options.runtime_dir, group)
        prepare_private_dir(os.path.join(options.runtime_dir, "gli"), group)
        token_check = None
        if options.tcp or options.web:  # before anything opens: a token that cannot be used refuses the start
            token_path = options.tcp_token or os.path.join(options.runtime_dir, TOKEN_FILE)
            token_check = TokenCheck(load_or_create(token_path, group), token_path)
        if options.web:  # the port too: one in use refuses the start
            from ..web.server import WebServer, parse_web

            web_host, web_port = parse_web(options.web)
            self.web_server = WebServer(web_host, web_port, token_check, token_file=token_check.path,
                                        auth_timeout_s=options.auth_timeout_s)
        raise_queue_budget()
        raise_descriptor_limit()
        if options.summary_path:  # refused now, not after a run of hours
            problem = output_problem(options.summary_path, "summary")
            if problem is not None:
                raise OutputError(problem)
        return token_check

    def _open_trace(self, scene: Scene) -> RealtimeScheduler:
        """The trace and its first event (the scene as it is now: the trace must not depend on the file
        later), and the loop."""
        trace_path = self.options.trace_path or scene.trace_file
        self.trace = (open_output(trace_path, "trace", append=True, group=self.group, buffering=1 << 16)
                      if trace_path else None)
        self.started = time.monotonic()  # the summary's wall_time_s (before model time 0)
        self.scheduler = scheduler = RealtimeScheduler(self.options.speed)
        self.recorder = Recorder(self.trace)
        self.run_id = uuid.uuid4().hex[:12]
        view = scene_view(scene)
        self.recorder.event({"t": 0.0, "ev": "run", "run": self.run_id,
                             "start": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="milliseconds"),
                             "scene": scene.name, "path": os.path.abspath(self.scene_path), "version": __version__,
                             "speed": self.options.speed, "scene_hash": view_hash(view), "scene_view": view})
        return scheduler

    def _open(self, scene: Scene, host: str | None, token_check: TokenCheck | None) -> None:
        """Everything the daemon serves, opened: the doors (from the door table), the scene's links, the pose
        sources, the TCP GLI, the control socket, the web view, the signals and the periodic work."""
        options, scheduler = self.options, self.scheduler
        setting = DoorSetting(scheduler, self.router, self.recorder, options, scene, host, self.clients, self.group)
        try:
            self.router.doors = open_doors(setting)
        finally:  # (what a failed start got as far as making, for shutdown())
            self.ros2 = setting.parts.get("ros2")
            self.network = setting.parts.get("network")
        self.live = LiveSources(scheduler, self.ros2)
        self.reloader = Reloader(scheduler, options, self._prepare_scene, self._apply_scene,
                                 lambda: len(self.router.links))
        self.reloader.scene = scene
        self._prepare_scene(scene)
        self.router.apply(scene)
        self._apply_sources(scene)
        if self.trace is not None and scene.trace_poses_s:
            self.router.world.sample_poses(scene.trace_poses_s * options.speed, self.recorder.event)
        if options.tcp:
            tcp_host, port = parse_tcp(options.tcp)
            self.tcp_listener = tcp_listener(tcp_host, port, scheduler, self.clients, self.router.port, token_check)
            log.info("TCP GLI on %s:%d: applications prove the token in %s (readable by the daemon's group)",
                     tcp_host, port, token_check.path)
        self.control = ControlServer(os.path.join(options.runtime_dir, "control.sock"), scheduler,
                                     self.status, self.reload, group=self.group,
                                     deferred={"NETWORK": self._network_status})
        if self.web_server is not None:
            from .webfeed import WebFeed

            self.web_server.start()
            self.web_feed = WebFeed(scheduler, self.router, self.recorder, self.web_server)
            self.web_feed.start()
            log.info("web view on %s: pages prove the token in %s (readable by the daemon's group); "
                     "`hilgate view` prints the address with it", self.web_server.url, token_check.path)
        scheduler.on_signal(signal.SIGHUP, lambda s: self.reload())  # answered in the log only
        scheduler.on_signal(signal.SIGTERM, self.stop)
        scheduler.on_signal(signal.SIGINT, self.stop)
        self._periodic()
        StaleWatch(scheduler, self.router).start()
        gc.collect()
        gc.freeze()  # everything built so far is long-lived: keep it out of the collector's walks
        log.info("hilgate %s started: scene %r (%s), %s (%s), endpoints: %s; run %s",
                 __version__, scene.name, os.path.abspath(self.scene_path), links_phrase(len(self.router.links)),
                 link_list(scene, host), endpoint_list(scene, host, options.runtime_dir, options.tcp), self.run_id)

    def _join_clock(self, scene: Scene, host: str | None) -> None:
        self.scheduler.start_clock()  # model time 0 now: the epoch the other hosts convert through
        self.network.start(scene)
        self.recorder.event({"t": 0.0, "ev": "network", "host": host, "zid": self.network.zid,
                             "epoch_ns": self.network.epoch_ns})
        log.info("joined the network as host %s (zenoh %s, prefix %s)", host, self.network.zid, self.network.prefix)

    def _prepare_scene(self, scene: Scene) -> None:
        """Checks a scene can be applied before anything changes (SceneError: refused untouched)."""
        if self.ros2 is not None:
            self.ros2.prepare(scene)

    def _apply_sources(self, scene: Scene) -> None:
        self.live.apply(scene, self.router.world.poses, self.router.world.local)
        if self.ros2 is not None:
            self.ros2.apply(scene)

    def _apply_scene(self, scene: Scene) -> None:
        """A reloaded scene, applied on the loop."""
        self.router.apply(scene)
        if self.network is not None:
            self.network.apply(scene)
        self._apply_sources(scene)
        self.scene = scene

    def _take_priority(self) -> None:
        """Real-time priority for this thread (the loop's) once everything is open: the start-up's work,
        and every thread made during it, ran at normal priority (:mod:`hilgate.core.priority`)."""
        if not self.options.realtime_priority:
            self.scheduling = current()
            return
        self.scheduling = raise_priority(self.options.realtime_priority)
        level = logging.INFO if self.scheduling.kind == "realtime" else logging.WARNING
        log.log(level, "scheduling: %s", self.scheduling.describe())

    def _network_status(self, request: dict, reply: Callable[[dict], Any]) -> None:
        if self.network is None:
            reply({"class": "ERROR", "error": "this daemon is not part of a network of hosts (no zenoh)"})
            return
        self.network.query_status(lambda hosts: reply({"class": "NETWORK", "hosts": hosts}))

    def _periodic(self) -> None:
        """Every half second of wall clock: flush the trace (a SIGKILL loses at most that) and redraw the
        status line; the systemd watchdog at half its timeout."""
        scheduler = self.scheduler

        def flush() -> None:
            if self.trace is not None:
                self.trace.flush()
            if self.options.status_line:
                sys.stderr.write("\r" + self.status_text() + "   ")
                sys.stderr.flush()
            scheduler.after_wall(0.5, flush)

        scheduler.after_wall(0.5, flush)
        interval = watchdog_interval()
        if interval:
            def ping() -> None:
                notify("WATCHDOG=1")
                scheduler.after_wall(interval, ping)

            ping()

    def status(self) -> dict[str, Any]:
        status = {**self.router.status(), "cameras": self.live.status(),
                  "scheduling": current(self.scheduling.asked, self.scheduling.notes).as_dict()}  # (the loop's thread)
        ros2 = self.ros2.status() if self.ros2 is not None else None
        if ros2 is not None:  # only once the daemon is on ROS 2
            status["ros2"] = {**ros2, "poses_in": self.live.ros2_status()}
        if self.tcp_listener is not None:  # what the TCP GLI refused, by cause; how many wait to authenticate
            status["tcp"] = {"refused": dict(self.clients.refused), "waiting": len(self.clients.pending)}
        if self.web_server is not None:  # where the web view is, the token its pages prove, what it refused
            status["web"] = {"url": self.web_server.url, "pages": self.web_server.clients,
                             "token_file": self.web_server.token_file, **self.web_server.status()}
        return status

    def status_text(self) -> str:
        status = self.router.status()
        links = status["links"]
        up = sum(1 for link in links if link["state"] == "up")
        tx = sum(link["tx_packets"] for link in links)
        rx = sum(link["rx_packets"] for link in links)
        drops = sum(link["drops"] for link in links)
        clients = sum(link.clients for link in self.router.links.values())
        return (f"hilgate t={self.scheduler.now():8.1f} s | {up}/{len(links)} links up | tx {tx} rx {rx} "
                f"drops {drops} | {clients} socket clients")

    def reload(self, reply: Callable[[bool, str], Any] | None = None) -> None:
        """Re-read the scene (:mod:`hilgate.daemon.reload`)."""
        self.reloader.reload(reply)

    def stop(self, signum: int | None = None) -> None:
        log.info("stopping (%s)", signal.Signals(signum).name if signum else "request")
        self.scheduler.stop()

    def shutdown(self) -> None:
        if self.stopping:
            return
        self.stopping = True
        notify("STOPPING=1")
        if self.options.status_line:
            sys.stderr.write("\n")
        router = self.router
        if self.options.summary_path and router is not None and router.world is not None:
            summary = self.recorder.summary(self.scene, router.world.seed, self.scheduler.now(),
                                            time.monotonic() - self.started, links=router.summary())
            try:
                write_summary(summary, self.options.summary_path, self.group)
            except OSError as exc:
                log.error("summary not written: %s", exc)
        if self.reloader is not None:
            self.reloader.cancel()
        for closer in (self.web_feed, self.web_server, self.live, self.control, self.tcp_listener, router,
                       self.network):
            if closer is not None:
                try:
                    closer.close()
                except Exception:
                    log.exception("while closing %r", closer)
        if self.ros2 is not None:  # last: the links' and sources' readers are gone
            try:
                self.ros2.shutdown()
            except Exception:
                log.exception("while leaving ROS 2")
        if self.trace is not None:
            self.recorder.close()
            self.trace.close()
        scheduler = self.scheduler
        if scheduler is not None:
            scheduler.close()
