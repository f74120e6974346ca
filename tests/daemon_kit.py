"""The tests' kit: the real daemon in a subprocess, the ``hilgate`` command, waiting, free ports.

The daemon is started with ``NOTIFY_SOCKET`` pointing at a datagram socket the test owns, so the
test waits for the very ``READY=1`` systemd would get (and checks that it comes only once every
endpoint is up).  Link ids carry a unique prefix; their POSIX queues are unlinked at the end, since
Linux charges them to the user until then (819 200 bytes by default).

Every wait is :func:`wait_until` with the one hang guard :data:`HANG_GUARD_S`: it returns as soon as its
condition holds, and the guard only stops a hang (a loaded machine running other suites makes a daemon
slow, never wrong).  The ``daemon_of`` fixture (conftest.py) starts daemons that are closed after the test.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import tty
import uuid

from hilgate.gli.queues import unlink_queues
from ports import free_port  # noqa: F401  (the tests' way to a port, kept here where they look for it)

HERE = os.path.dirname(os.path.abspath(__file__))
PEER = os.path.join(HERE, "peers", "dccomms_peer.py")
SCENE_HEAD = """\
channels: {ac: {speed_mps: 1500}}
vehicles:
  va: {pose: {static: [0, 0, 0]}}
  vb: {pose: {static: [150, 0, 0]}}
"""
"""What most daemon tests' scenes start with: one acoustic channel, two vehicles 150 m apart (links follow)."""
HANG_GUARD_S = 90.0


def quick_scene(name: str, a: str, b: str, distance_m: float = 10, bitrate_bps: float = 1e6,
                speed_mps: float = 1500) -> str:
    """Two vl2b links (addresses 1 and 2) ``distance_m`` apart, no pose lines in the trace; by default 10 m
    at 1 Mb/s (a frame crosses in microseconds)."""
    return f"""\
name: {name}
channels: {{ac: {{speed_mps: {speed_mps}}}}}
vehicles: {{va: {{pose: {{static: [0, 0, 0]}}}}, vb: {{pose: {{static: [{distance_m}, 0, 0]}}}}}}
links:
  {a}: {{vehicle: va, address: 1, packet: vl2b, bitrate_bps: {bitrate_bps}}}
  {b}: {{vehicle: vb, address: 2, packet: vl2b, bitrate_bps: {bitrate_bps}}}
trace: {{poses_s: 0}}
"""


def two_links(daemon_of, scene) -> tuple["Daemon", str, str]:
    """A running daemon of ``scene(a, b)`` with two fresh link ids: ``(daemon, a, b)``."""
    a, b = unique("a"), unique("b")
    return daemon_of(scene(a, b), [a, b]), a, b
"""The one bound on every wait of the tests: a hang guard, never a speed requirement."""


def unique(prefix: str = "t") -> str:
    return f"{prefix}{uuid.uuid4().hex[:8]}"


def wait_until(predicate, what: str = "a condition", timeout: float = HANG_GUARD_S, every: float = 0.05):
    """Poll ``predicate`` until it returns something true, and return that; fail after ``timeout`` s
    (a hang guard) saying ``what`` was awaited (a callable: called for the message, e.g. a daemon's log)."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what() if callable(what) else what}")
        time.sleep(every)


def in_background(loop) -> tuple[threading.Event, threading.Thread]:
    """Run ``loop(stop)`` on a daemon thread (a peer that streams, a reader) until the event ``stop`` it is
    handed is set (``stop.set(); thread.join()``)."""
    stop = threading.Event()
    thread = threading.Thread(target=loop, args=(stop,), daemon=True)
    thread.start()
    return stop, thread


class PluggablePty:
    """A serial device on a pty at ``path`` (a symlink, as udev makes one) that a test unplugs and plugs
    again; what the host writes is handed to :meth:`answer` on a thread of its own, and its answer
    written back."""

    def __init__(self, path: str):
        self.path = path
        self.master: int | None = None
        self.lock = threading.Lock()
        self.plug()
        self.stop, self.thread = in_background(self._serve)

    def plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        if os.path.lexists(self.path):
            os.unlink(self.path)
        os.symlink(os.ttyname(slave), self.path)
        with self.lock:
            self.master, self.slave = master, slave
            self.plugged()

    def plugged(self) -> None:
        """A new device is on the line (a subclass starts its protocol state afresh here)."""

    def unplug(self) -> None:
        with self.lock:
            os.unlink(self.path)
            os.close(self.master)
            os.close(self.slave)
            self.master = None

    def write(self, data: bytes) -> None:
        with self.lock:
            if self.master is not None:
                os.write(self.master, data)

    def answer(self, data: bytes) -> bytes:
        """What the device answers to ``data`` from the host (nothing, here)."""
        return b""

    def _serve(self, stop: threading.Event) -> None:
        while not stop.is_set():
            with self.lock:  # held while the descriptor is used: unplug() must not close it meanwhile, or
                master = self.master  # its number, reused by the test's next socket, would be read here
                data = b""
                if master is not None:
                    try:
                        ready, _, _ = select.select([master], [], [], 0.02)
                        data = os.read(master, 4096) if ready else b""
                    except (OSError, ValueError):
                        data = b""
                if data:
                    reply = self.answer(data)
                    if reply:
                        os.write(master, reply)
            if not data:
                time.sleep(0.005)

    def close(self) -> None:
        self.stop.set()
        self.thread.join()


def hilgate(*args: str, **kwargs) -> subprocess.CompletedProcess:
    """``hilgate ARGS`` as a user runs it (its output captured as text); ``input=`` for its stdin."""
    kwargs.setdefault("timeout", 3 * HANG_GUARD_S)
    return subprocess.run([sys.executable, "-m", "hilgate", *args], capture_output=True, text=True, **kwargs)


def _unlimited_queue_budget() -> None:
    """In the daemon's process: LimitMSGQUEUE=infinity, as the systemd unit has it, where allowed (the
    user's POSIX-queue budget is shared by every test run on the machine)."""
    import resource

    try:
        resource.setrlimit(resource.RLIMIT_MSGQUEUE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    except (ValueError, OSError):
        pass


def _in_order(*steps):
    """One ``preexec_fn`` that runs each of ``steps`` (None: none) in the daemon's process before it starts."""
    steps = [step for step in steps if step is not None]
    if not steps:
        return None

    def run() -> None:
        for step in steps:
            step()

    return run


SHORT_PREFIX = "hgrt-"
UNIX_PATH_ROOM = 60  # a runtime directory longer than this leaves too little of AF_UNIX's 107 bytes for gli/ID.sock


def _short_enough(runtime: str) -> str:
    """The runtime directory under the test's folder, or, when that path is too long for the daemon's Unix
    sockets (pytest's folders grow with the run's number, xdist's worker and the test's name: AF_UNIX path
    too long was seen), a short one of its own in the system's temporary folder, removed at close."""
    if len(runtime) <= UNIX_PATH_ROOM:
        return runtime
    return tempfile.mkdtemp(prefix=SHORT_PREFIX)


class Daemon:
    """The daemon ``hilgate run`` in a subprocess; ``preexec``: run in its process before it starts (to take
    a privilege away, as a host would not grant it)."""

    def __init__(self, tmp_path, scene_text: str, links: list[str], *args: str, env: dict | None = None,
                 runtime: str | None = None, queue_budget_unlimited: bool = False, preexec=None,
                 launch: tuple[str, ...] = ()):
        """``launch``: a command the daemon runs under (``ip netns exec NAME``: tests/netns_kit.py)."""
        self.tmp = tmp_path
        self.links = links
        self.scene = tmp_path / "scene.yaml"
        self.scene.write_text(scene_text)
        self.runtime = runtime or _short_enough(str(tmp_path / "rt"))
        self.trace = tmp_path / "trace.jsonl"
        self.summary = tmp_path / "summary.json"
        self.notify_path = str(tmp_path / "notify.sock")
        self.notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.notify.bind(self.notify_path)
        self.log = open(tmp_path / "daemon.log", "w+")
        self._start = dict(
            args=[*launch, sys.executable, "-m", "hilgate", "-v", "run", str(self.scene), "--runtime-dir", self.runtime,
                  "--trace", str(self.trace), "--summary", str(self.summary), "--no-status-line", *args],
            stdout=self.log, stderr=subprocess.STDOUT, env=dict(os.environ, NOTIFY_SOCKET=self.notify_path, **(env or {})),
            preexec_fn=_in_order(_unlimited_queue_budget if queue_budget_unlimited else None, preexec))
        self.process = subprocess.Popen(**self._start)
        self.notifications: list[str] = []
        self.budget_waits = 0

    def _waiting_for_queues(self) -> bool:
        """The daemon could not start because this user's POSIX-queue budget (shared by every test run on
        the machine, and by the other workers of this one) was used up: it removed what it had made, and
        it is started again once the others may have let go (another test's wait, not this test's failure)."""
        if "the queue budget of this user is used up" not in self.output() or any(
                "READY=1" in n.split("\n") for n in self.notifications):
            return False
        self.budget_waits += 1
        time.sleep(min(2.0, 0.2 * self.budget_waits))
        self.log.seek(0)
        self.log.truncate()
        self.process = subprocess.Popen(**self._start)
        return True

    def wait_for(self, word: str, timeout: float = HANG_GUARD_S) -> list[str]:
        """Wait for a notify datagram containing ``word``; returns its lines."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.notify.settimeout(max(0.01, min(0.5, deadline - time.monotonic())))
            try:
                data = self.notify.recv(4096).decode()
            except socket.timeout:
                if self.process.poll() is not None and not self._waiting_for_queues():
                    raise AssertionError(f"daemon exited with {self.process.returncode}:\n{self.output()}")
                continue
            self.notifications.append(data)
            if word in data.split("\n"):
                return data.split("\n")
        raise AssertionError(f"no {word} from the daemon within {timeout} s:\n{self.output()}")

    def output(self) -> str:
        self.log.flush()
        self.log.seek(0)
        return self.log.read()

    def control(self, request: dict) -> dict:
        from hilgate.control_client import Control

        with Control(self.runtime, timeout=10) as control:
            assert control.version["class"] == "VERSION"
            return control.request(request)

    def status(self) -> dict:
        return self.control({"class": "STATUS"})

    def link_status(self, link: str) -> dict:
        return next(l for l in self.status()["links"] if l["id"] == link)

    def vehicle(self, name: str) -> dict:
        """The vehicle ``name`` as STATUS shows it (position, source, age)."""
        return next(v for v in self.status()["vehicles"] if v["name"] == name)

    def alive(self) -> bool:
        if self.process.poll() is not None:
            raise AssertionError(f"daemon exited with {self.process.returncode}:\n{self.output()}")
        return True

    def wait_clients(self, link: str, count: int = 1) -> None:
        """Wait until ``count`` socket clients are attached to ``link``: a client process started just
        before (``hilgate listen``, ``hilgate app``) gets only the frames sent once it is attached, and
        on a loaded host its start-up alone can take seconds."""
        wait_until(lambda: self.alive() and self.link_status(link)["clients"] >= count,
                   lambda: f"{count} clients on {link}:\n{self.output()}")

    def wait_up(self, *links: str) -> None:
        """Wait until every one of ``links`` is up (a real modem's port opened)."""
        def up() -> bool:
            states = {l["id"]: l["state"] for l in self.status()["links"]}
            return self.alive() and all(states[link] == "up" for link in links)

        wait_until(up, lambda: f"links {', '.join(links)} up: {self.status()['links']}\n{self.output()}", every=0.1)

    def reload(self, scene_text: str | None = None) -> None:
        if scene_text is not None:
            self.scene.write_text(scene_text)
        self.process.send_signal(signal.SIGHUP)
        self.wait_for("RELOADING=1")
        self.wait_for("READY=1")

    def peer(self, link: str, *args: str) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, PEER, link, *args], stdout=subprocess.PIPE, text=True)

    def trace_events(self) -> list[dict]:
        return [json.loads(line) for line in self.trace.read_text().splitlines()]

    def trace_so_far(self) -> list[dict]:
        """The trace of a daemon still running: whole lines only (the last may be half written)."""
        events = []
        for line in self.trace.read_text().splitlines():
            try:
                events.append(json.loads(line))
            except ValueError:
                pass
        return events

    def stop(self) -> int:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(20)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.returncode

    def close(self) -> None:
        self.stop()
        self.notify.close()
        self.log.close()
        unlink_queues(self.links)
        if os.path.basename(self.runtime).startswith(SHORT_PREFIX):
            shutil.rmtree(self.runtime, ignore_errors=True)


def walk_a_live_vehicle(daemon: Daemon, topside: str, bluerov: str, move_away, fall_silent) -> dict:
    """The walk every live pose source takes (MAVLink, ROS 2): the vehicle ``bluerov`` 150 m from
    ``topside`` and 5 m deep hears a frame; ``move_away()`` puts it at 300 m and it hears another;
    ``fall_silent()`` stops its source, its pose goes stale and is dropped, and a third frame is lost.
    Returns the vehicle's status at its first pose (the caller checks its source)."""
    from hilgate.client import Link

    wait_until(lambda: daemon.vehicle("bluerov")["position"] is not None, "the first pose")
    first = daemon.vehicle("bluerov")
    assert first["position"] == [150.0, 0.0, 5.0]
    with Link.open(topside, runtime_dir=daemon.runtime) as top, Link.open(bluerov, runtime_dir=daemon.runtime) as rov:
        top.send(b"near", dst=2)
        assert rov.recv(timeout=30).data == b"near"
        move_away()
        wait_until(lambda: daemon.vehicle("bluerov")["position"] == [300.0, 0.0, 5.0], "the new pose")
        top.send(b"away", dst=2)
        assert rov.recv(timeout=30).data == b"away"
        fall_silent()
        wait_until(lambda: daemon.vehicle("bluerov")["position"] is None, "the stale pose dropped")
        top.send(b"lost", dst=2)
        assert rov.recv(timeout=1.5) is None
    return first


def assert_the_walk_traced(daemon: Daemon) -> None:
    """Stop the daemon of :func:`walk_a_live_vehicle` and hold its trace to the walk: 9 bytes on air = 72 ms,
    then the distance to the vehicle 5 m deep, 150 m then 300 m away; the third frame dropped with no pose."""
    import math

    daemon.stop()
    events = daemon.trace_events()
    enq = {e["pkt"]: e["t"] for e in events if e.get("ev") == "enq"}
    delays = [round(e["t"] - enq[e["pkt"]], 6) for e in events if e.get("ev") == "rx"]
    assert delays == [round(0.072 + math.hypot(150, 5) / 1500, 6), round(0.072 + math.hypot(300, 5) / 1500, 6)]
    assert [e["cause"] for e in events if e.get("ev") == "err"] == ["no_pose"]


def peer_events(process: subprocess.Popen, timeout: float = 90.0) -> list[dict]:
    out, _ = process.communicate(timeout=timeout)
    return [json.loads(line) for line in out.splitlines() if line.strip()]
