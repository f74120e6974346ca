"""The daemon as the benchmarks run it: ``hilgate run`` in a subprocess of a temporary directory, up
once it says READY=1 on its notify socket (as systemd would hear it), asked over its control socket
(:mod:`hilgate.control_client`), and stopped with its resource usage.  gli_roundtrip.py,
realtime_lateness.py, multihost.py, many_links.py and web_cost.py start theirs here.

A daemon that could not make its queues because this user's POSIX-queue budget is used up (by another
run on the machine) is started again, for up to :data:`BUDGET_WAIT_S`: the figures are measured once it
is up, never while it waits.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

from placement import pinned_command

from hilgate.control_client import request
from hilgate.gli.queues import unlink_queues

BUDGET_WAIT_S = 120.0
BUDGET_USED_UP = "the queue budget of this user is used up"
CLOCK_TICK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """CPU seconds (user + system, every thread) process ``pid`` has used so far (/proc, so it runs on)."""
    with open(f"/proc/{pid}/stat") as handle:
        fields = handle.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICK


class Daemon:
    """``hilgate run`` on ``scene_text`` (its links with queues are ``links``, unlinked on close) with
    ``args``, in ``directory`` (a new temporary one if None, removed on close) under ``name``: its scene ``NAME.yaml``,
    runtime directory ``NAME``, log ``NAME.log`` (its output stays out of the benchmark's).  ``cpu``:
    the one CPU it runs on (None: the kernel's choice).  ``launch``: the Python arguments before
    ``run`` (default ``-m hilgate``).  ``within``: a command it runs under that ``exec``s it in place
    (``ip netns exec NAME``: the process id stays the daemon's)."""

    def __init__(self, scene_text: str, links: tuple[str, ...] = (), args: tuple[str, ...] = (),
                 cpu: int | None = None, directory: str | None = None, name: str = "daemon",
                 launch: tuple[str, ...] = ("-m", "hilgate"), ready_timeout: float = 60.0,
                 within: tuple[str, ...] = ()):
        self.made_dir = directory is None  # (removed on close, with the log)
        self.dir = directory or tempfile.mkdtemp(prefix="hilgate-bench-")
        self.links = links
        self.runtime = os.path.join(self.dir, name)
        scene = os.path.join(self.dir, f"{name}.yaml")
        with open(scene, "w") as handle:
            handle.write(scene_text)
        notify_path = os.path.join(self.dir, f"{name}.notify")
        self.notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.notify.bind(notify_path)
        self.log_path = os.path.join(self.dir, f"{name}.log")
        self.command = pinned_command([*within, sys.executable, *launch, "run", scene, "--runtime-dir", self.runtime,
                                       "--no-status-line", *args], cpu)
        self.env = dict(os.environ, NOTIFY_SOCKET=notify_path)
        self.process: subprocess.Popen | None = None
        try:
            self._start(ready_timeout)
        except BaseException:
            self.close()
            raise

    def _start(self, ready_timeout: float) -> None:
        budget_deadline = time.monotonic() + BUDGET_WAIT_S
        while True:
            with open(self.log_path, "w") as log:
                self.process = subprocess.Popen(self.command, env=self.env, stdout=log, stderr=subprocess.STDOUT)
            if self._ready(ready_timeout):
                return
            output = self.output()
            if BUDGET_USED_UP in output and time.monotonic() < budget_deadline:
                time.sleep(1.0)  # another run holds the queues: start again once it may have let go
                continue
            raise RuntimeError(f"the daemon did not start (exit {self.process.returncode}):\n{output[-2000:]}")

    def _ready(self, timeout: float) -> bool:
        """Wait for READY=1, or for the daemon to exit (False)."""
        deadline = time.monotonic() + timeout
        self.notify.settimeout(0.5)
        while time.monotonic() < deadline:
            try:
                if b"READY=1" in self.notify.recv(4096).split(b"\n"):
                    return True
            except socket.timeout:
                if self.process.poll() is not None:
                    return False
        self.process.kill()
        self.process.wait()
        return False

    def output(self) -> str:
        with open(self.log_path, errors="replace") as handle:
            return handle.read()

    def control(self, message: dict) -> dict:
        return request(message, self.runtime)

    def status(self) -> dict:
        return self.control({"class": "STATUS"})

    def close(self) -> "os.struct_rusage | None":
        """Stop the daemon (SIGTERM; SIGKILL after 30 s); its resource usage (CPU), or None if it was
        already reaped."""
        usage = None
        process = self.process
        if process is not None and process.returncode is None:
            process.send_signal(signal.SIGTERM)
            deadline = time.monotonic() + 30
            try:
                while True:
                    pid, status, usage = os.wait4(process.pid, os.WNOHANG)
                    if pid:
                        process.returncode = os.waitstatus_to_exitcode(status)
                        break
                    if time.monotonic() > deadline:
                        process.kill()
                        _, status, usage = os.wait4(process.pid, 0)
                        process.returncode = os.waitstatus_to_exitcode(status)
                        break
                    time.sleep(0.01)
            except ChildProcessError:
                usage = None
        self.notify.close()
        unlink_queues(self.links)
        if self.made_dir:
            shutil.rmtree(self.dir, ignore_errors=True)
        return usage
