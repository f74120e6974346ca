"""``hilgate run``: the daemon.  Loads the scene, opens every endpoint, tells systemd it is ready,
runs the model in real time, reloads on SIGHUP and stops cleanly (trace complete) on SIGTERM/SIGINT."""

from __future__ import annotations

import datetime
import gc
import logging
import os
import signal
import socket
import sys
import time
import uuid
from typing import Any, Callable

from .. import __version__
from .access import (lock_directory, prepare_lock_directory, prepare_private_dir, raise_descriptor_limit,
                     resolve_group)
from .control import ControlServer
from ..drivers.emulators import EmulatorDoor
from ..gli.queues import QueueDoor, forget_created, plan_message_size, raise_queue_budget, unlink_created
from ..gli.sockets import ClientLimits, SocketDoor, tcp_listener
from ..gli.unet_door import UnetDoor
from ..gli.token import TOKEN_FILE, TokenCheck, load_or_create
from .live_sources import LiveSources
from .ros2_bridge import Ros2Bridge
from ..core.priority import Scheduling, current, raise_priority
from ..core.realtime import RealtimeScheduler
from ..sim.recorder import Recorder
from .router import Router
from .stale_poses import StaleWatch
from .network import Network
from ..gli.zenoh_auth import CredentialError, Identity, load_identity
from ..scene import Scene, SceneError, load_scene
from ..scene.hosts import HOST_NAME, ZenohSpec
from ..scene.links import require_narrow_addresses
from ..scene.view import scene_view, view_hash
from ..scene.worker import SceneJob, request_for
from ..core.notify import notify, watchdog_interval
from ..core.outputs import OutputError, open_output, output_problem
from ..sim.simulate import write_summary

log = logging.getLogger(__name__)


def parse_tcp(value: str) -> tuple[str, int]:
    """``PORT`` or ``HOST:PORT``; loopback unless a host is given.  ValueError says what is wrong."""
    host, _, port = str(value).rpartition(":")
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"{value!r} is not [HOST:]PORT with a port from 1 to 65535")
    return (host.strip("[]") or "127.0.0.1"), int(port)


def _link_list(scene: Scene, host: str | None, limit: int = 12) -> str:
    parts = [f"{link.id}={link.backend}" for link in scene.links.values() if host is None or link.host == host]
    if len(parts) > limit:
        parts = parts[:limit] + [f"… {len(parts) - limit} more"]
    return ", ".join(parts)


def _links(n: int) -> str:
    return f"{n} link" if n == 1 else f"{n} links"


def _endpoint_list(scene: Scene, host: str | None, runtime_dir: str, tcp: str | None) -> str:
    """The endpoints this daemon opened, for its start line: only the kinds its links use."""
    served = [link for link in scene.links.values() if host is None or link.host == host]
    parts = []
    queues = sum("mq" in link.gli for link in served)
    if queues:
        parts.append(f"POSIX queues /ID_{{tx,rx}}_dlnk_phy ({_links(queues)})")
    sockets = sum("socket" in link.gli for link in served)
    if sockets:
        parts.append(f"sockets {runtime_dir}/gli/ID.sock ({_links(sockets)})")
    if tcp:
        parts.append(f"TCP {tcp}")
    for link in served:
        if link.unet:
            door = dict(link.unet)
            parts.append(f"{link.id} as a UnetStack node at {door['host']}:{door['tcp']}")
    for link in served:
        emulate = dict(link.emulate)
        if emulate:
            where = f"pty {emulate['pty']}" if emulate.get("pty") else f"TCP port {emulate.get('tcp')}"
            parts.append(f"{link.id} as an emulated {emulate.get('protocol')} modem at {where}")
    parts.append(f"control {runtime_dir}/control.sock")
    return ", ".join(parts)


class Daemon:
    def __init__(self, scene_path: str, overrides: list[str] | tuple[str, ...] = (), runtime_dir: str = "",
                 speed: float = 1.0, tcp: str | None = None, trace_path: str | None = None,
                 summary_path: str | None = None, until: float | None = None, status_line: bool = False,
                 gli_backlog: int = 1000, group: str | None = None, max_clients: int = 256,
                 max_link_clients: int = 32, plugins: list[str] | tuple[str, ...] = (),
                 preset_dirs: list[str] | tuple[str, ...] = (), host: str | None = None,
                 zenoh_connect: list[str] | tuple[str, ...] = (), zenoh_listen: list[str] | tuple[str, ...] = (),
                 clock_offset_s: float = 0.0, tcp_token: str | None = None,
                 zenoh_credentials: str | None = None, zenoh_insecure: bool = False, web: str | None = None,
                 auth_timeout_s: float = 5.0, realtime_priority: int = 0):
        self.web = web
        self.auth_timeout_s = auth_timeout_s
        self.realtime_priority = realtime_priority
        self.scheduling = Scheduling()  # what the loop thread runs at (status): set as the loop starts
        self.web_server: Any = None
        self.web_feed: Any = None
        self.tcp_token = tcp_token
        self.host = host
        self.zenoh_credentials = zenoh_credentials
        self.zenoh_insecure = zenoh_insecure
        self.zenoh_connect = list(zenoh_connect)
        self.zenoh_listen = list(zenoh_listen)
        self.clock_offset_s = clock_offset_s
        self.network: Network | None = None
        self.plugins = list(plugins)
        self.preset_dirs = list(preset_dirs)
        self.group_name = group
        self.max_clients = max_clients
        self.max_link_clients = max_link_clients
        self.scene_path = scene_path
        self.overrides = list(overrides)
        self.runtime_dir = runtime_dir
        self.speed = speed
        self.tcp = tcp
        self.trace_path = trace_path
        self.summary_path = summary_path
        self.until = until
        self.status_line = status_line
        self.gli_backlog = gli_backlog
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
        self.stopping = False
        self.started = time.monotonic()
        self._reload_job: SceneJob | None = None
        self._reload_again = False
        self._reload_waiting: list[Callable[[bool, str], Any]] = []
        self._reload_next: list[Callable[[bool, str], Any]] = []

    def run(self) -> int:
        scene = load_scene(self.scene_path, self.overrides, plugins=self.plugins,
                           preset_dirs=self.preset_dirs)  # a bad scene never half-starts
        require_narrow_addresses(scene.links.values())
        self.scene = scene
        host = self._host(scene)
        group = resolve_group(self.group_name)
        prepare_private_dir(self.runtime_dir, group)
        prepare_private_dir(os.path.join(self.runtime_dir, "gli"), group)
        token_check = None
        if self.tcp or self.web:  # before anything opens: a token that cannot be used refuses the start
            token_path = self.tcp_token or os.path.join(self.runtime_dir, TOKEN_FILE)
            token_check = TokenCheck(load_or_create(token_path, group), token_path)
        if self.web:  # the port too: one in use refuses the start
            from ..web.server import WebServer, parse_web

            web_host, web_port = parse_web(self.web)
            self.web_server = WebServer(web_host, web_port, token_check, token_file=token_check.path,
                                        auth_timeout_s=self.auth_timeout_s)
        raise_queue_budget()
        raise_descriptor_limit()
        trace_path = self.trace_path or scene.trace_file
        if self.summary_path:  # refused now, not after a run of hours
            problem = output_problem(self.summary_path, "summary")
            if problem is not None:
                raise OutputError(problem)
        self.group = group
        self.trace = (open_output(trace_path, "trace", append=True, group=group, buffering=1 << 16)
                      if trace_path else None)
        self.started = time.monotonic()  # the summary's wall_time_s (before model time 0)
        self.scheduler = scheduler = RealtimeScheduler(self.speed)
        self.recorder = Recorder(self.trace)
        self.run_id = uuid.uuid4().hex[:12]
        view = scene_view(scene)  # the scene as it is now: the trace must not depend on the file later
        self.recorder.event({"t": 0.0, "ev": "run", "run": self.run_id,
                             "start": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="milliseconds"),
                             "scene": scene.name, "path": os.path.abspath(self.scene_path), "version": __version__,
                             "speed": self.speed, "scene_hash": view_hash(view), "scene_view": view})
        lock_dir = lock_directory(self.runtime_dir)
        prepare_lock_directory(lock_dir)
        self.router = Router(scheduler, self.recorder, max_link_clients=self.max_link_clients, host=host,
                             lock_dir=lock_dir)
        self.clients = ClientLimits(self.max_clients, self.max_link_clients, auth_timeout_s=self.auth_timeout_s)
        self.router.doors = [
            QueueDoor(scheduler, plan_message_size(sum(1 for l in scene.links.values()
                                                        if host in (None, l.host) and "mq" in l.gli)),
                      self.gli_backlog, group),
            SocketDoor(os.path.join(self.runtime_dir, "gli"), scheduler, self.clients, self.router.port, group),
            EmulatorDoor(scheduler),
            UnetDoor(scheduler),
        ]
        self.ros2 = Ros2Bridge(scheduler, self.router, self.scene_path)
        self.router.doors.append(self.ros2)  # opens nothing, and loads no DDS, for links not on ROS 2
        self.tcp_listener = None
        self.control = None
        self.live = LiveSources(scheduler, self.ros2)
        try:
            if host is not None:
                spec = scene.zenoh or ZenohSpec()
                self.network = Network(scheduler, self.router, self.recorder, host, spec, self.zenoh_connect,
                                       self.zenoh_listen, self.clock_offset_s, self._identity(spec, host))
                self.router.doors.append(self.network.open())
                self.network.claim(scene)  # before anything opens: a refused daemon touches nothing
                self.router.network = self.network
            self.ros2.prepare(scene)
            self.router.apply(scene)
            self.live.apply(scene, self.router.world.poses, self.router.world.local)
            self.ros2.apply(scene)
            if self.trace is not None and scene.trace_poses_s:
                self.router.world.sample_poses(scene.trace_poses_s * self.speed, self.recorder.event)
            if self.tcp:
                host, port = parse_tcp(self.tcp)
                self.tcp_listener = tcp_listener(host, port, scheduler, self.clients, self.router.port, token_check)
                log.info("TCP GLI on %s:%d: applications prove the token in %s (readable by the daemon's group)",
                         host, port, token_check.path)
            self.control = ControlServer(os.path.join(self.runtime_dir, "control.sock"), scheduler,
                                         self.status, self.reload, group=group,
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
                     __version__, scene.name, os.path.abspath(self.scene_path), _links(len(self.router.links)),
                     _link_list(scene, host), _endpoint_list(scene, host, self.runtime_dir, self.tcp), self.run_id)
        except BaseException:
            removed = unlink_created()  # it never said READY: its queues would only cost the user's budget
            if removed:
                log.info("start-up failed: removed the %d queues this daemon had created", len(removed))
            self.shutdown()
            raise
        forget_created()  # from now on applications may hold them: never unlinked by the daemon
        if self.network is not None:
            scheduler.start_clock()  # model time 0 now: the epoch the other hosts convert through
            self.network.start(scene)
            self.recorder.event({"t": 0.0, "ev": "network", "host": host, "zid": self.network.zid,
                                 "epoch_ns": self.network.epoch_ns})
            log.info("joined the network as host %s (zenoh %s, prefix %s)", host, self.network.zid,
                     self.network.prefix)
        self._take_priority()
        try:
            notify("READY=1", f"STATUS=running {scene.name!r}: {len(self.router.links)} links",
                   f"MAINPID={os.getpid()}")
            scheduler.run(self.until if self.until is not None else float("inf"))
        finally:
            self.shutdown()
        return 0

    def _take_priority(self) -> None:
        """Real-time priority for this thread (the loop's) once everything is open: the start-up's work,
        and every thread made during it, ran at normal priority (:mod:`hilgate.core.priority`)."""
        if not self.realtime_priority:
            self.scheduling = current()
            return
        self.scheduling = raise_priority(self.realtime_priority)
        level = logging.INFO if self.scheduling.kind == "realtime" else logging.WARNING
        log.log(level, "scheduling: %s", self.scheduling.describe())

    def _host(self, scene: Scene) -> str | None:
        """This daemon's host name in a scene spread over hosts (None: the scene is for one daemon)."""
        if not (scene.multi_host or self.host or self.zenoh_connect or self.zenoh_listen):
            return None
        host = self.host or socket.gethostname().split(".")[0]
        if not HOST_NAME.fullmatch(host):
            raise SceneError("--host", 0, "", f"{host!r} is not a host name (letters, digits, '_', '.', '-')")
        if self.speed != 1.0:
            raise SceneError("--speed", 0, "", "a daemon of several hosts runs at real time (--speed 1): model "
                                               "times cross hosts through the UNIX clock")
        if scene.hosts and host not in scene.hosts:
            raise SceneError(self.scene_path, 0, "", f"this daemon is host {host!r} but the scene's hosts are "
                                                      f"{', '.join(scene.hosts)}: give --host")
        return host

    def _identity(self, spec: ZenohSpec, host: str) -> Identity | None:
        """This host's credentials, or None when the network is insecure, asked for in so many words."""
        path = self.zenoh_credentials or spec.credentials
        if path is None:
            if not (spec.insecure or self.zenoh_insecure):
                raise SceneError(self.scene_path, 0, "", "a scene of several hosts says where the lab's credentials "
                                 "are (zenoh: {credentials: DIR}, from: hilgate network init DIR --hosts ...) or "
                                 "that the network is open to anyone who reaches it (zenoh: {insecure: true})")
            log.warning("INSECURE network: Zenoh without credentials (zenoh.insecure): anyone who reaches %s "
                        "can send frames, forge hosts and read everything",
                        ", ".join(self.zenoh_listen or spec.listen))
            return None
        try:
            identity = load_identity(path, host, "host")
        except CredentialError as exc:
            raise SceneError(self.scene_path, 0, "", str(exc)) from None
        missing = [name for name in (self.scene.hosts if self.scene else ()) if name not in identity.hosts]
        if missing:
            log.warning("the credentials in %s do not list host(s) %s of the scene: their daemons will not be "
                        "heard (run hilgate network init again with every host)", identity.directory, ", ".join(missing))
        return identity

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
            if self.status_line:
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
        ros2 = self.ros2.status()
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
        """Re-read the scene (SIGHUP, ``systemctl reload``, a control RELOAD).  The file is loaded
        and validated in a worker process (:mod:`hilgate.scene.worker`) while the loop keeps
        delivering; a valid scene is applied on the loop.  Every outcome is answered to ``reply``,
        logged in one line and followed by READY=1.  A reload asked while one runs is done once
        more after it, so the last version of the file always wins."""
        if self._reload_job is not None:
            self._reload_again = True
            if reply is not None:
                self._reload_next.append(reply)
            return
        if reply is not None:
            self._reload_waiting.append(reply)
        notify("RELOADING=1", f"MONOTONIC_USEC={time.monotonic_ns() // 1000}", "STATUS=reloading")
        log.info("reloading %s", self.scene_path)
        try:
            self._reload_job = SceneJob(self.scheduler, self._scene_request(), self._reload_loaded)
        except Exception as exc:  # cannot even start the worker (out of processes, memory…)
            self._reload_finished(False, f"cannot start the scene loader: {type(exc).__name__}: {exc}")

    def _scene_request(self) -> dict[str, Any]:
        return request_for(self.scene_path, self.overrides, plugins=self.plugins, preset_dirs=self.preset_dirs)

    def _reload_loaded(self, scene: Scene | None, error: str | None) -> None:
        self._reload_job = None
        if scene is None:
            self._reload_finished(False, error or "unknown error")
            return
        try:
            require_narrow_addresses(scene.links.values())
        except SceneError as exc:
            self._reload_finished(False, str(exc))
            return
        try:
            self.ros2.prepare(scene)
        except SceneError as exc:
            self._reload_finished(False, str(exc))
            return
        try:
            self.router.apply(scene)
            if self.network is not None:
                self.network.apply(scene)
            self.live.apply(scene, self.router.world.poses, self.router.world.local)
            self.ros2.apply(scene)
            self.scene = scene
        except Exception as exc:  # e.g. a new link's port or queue cannot be opened
            log.debug("reload failed while applying", exc_info=True)
            self._reload_finished(False, f"applying the new scene failed (it may be applied in part): "
                                         f"{type(exc).__name__}: {exc}")
            return
        self._reload_finished(True, "")

    def _reload_finished(self, ok: bool, error: str) -> None:
        scene = self.scene
        if ok:
            log.info("reloaded %s: %d links", self.scene_path, len(self.router.links))
            notify("READY=1", f"STATUS=running {scene.name!r}: {len(self.router.links)} links")
        else:
            error = " ".join(error.split())
            log.error("reload refused, the running scene stays: %s", error)
            notify("READY=1", f"STATUS=reload refused: {error}"[:1000])
        waiting, self._reload_waiting = self._reload_waiting, []
        for reply in waiting:
            try:
                reply(ok, error)
            except Exception:
                log.exception("answering a reload request failed")
        if self._reload_again:
            self._reload_again = False
            self._reload_waiting, self._reload_next = self._reload_next, []
            self.reload()

    def stop(self, signum: int | None = None) -> None:
        log.info("stopping (%s)", signal.Signals(signum).name if signum else "request")
        self.scheduler.stop()

    def shutdown(self) -> None:
        if self.stopping:
            return
        self.stopping = True
        notify("STOPPING=1")
        if self.status_line:
            sys.stderr.write("\n")
        router = self.router
        if self.summary_path and router is not None and router.world is not None:
            summary = self.recorder.summary(self.scene, router.world.seed, self.scheduler.now(),
                                            time.monotonic() - self.started, links=router.summary())
            try:
                write_summary(summary, self.summary_path, self.group)
            except OSError as exc:
                log.error("summary not written: %s", exc)
        if self._reload_job is not None:
            self._reload_job.cancel()
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
