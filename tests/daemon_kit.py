"""Running the real daemon in a subprocess for tests, and cleaning up after it.

The daemon is started with ``NOTIFY_SOCKET`` pointing at a datagram socket the test owns, so the
test waits for the very ``READY=1`` systemd would get (and checks that it comes only once every
endpoint is up).  Link ids carry a unique prefix; their POSIX queues are unlinked at the end, since
Linux charges them to the user until then (819 200 bytes by default).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import uuid

from hilgate.gli.queues import unlink_queues

HERE = os.path.dirname(os.path.abspath(__file__))
PEER = os.path.join(HERE, "peers", "dccomms_peer.py")


def unique(prefix: str = "t") -> str:
    return f"{prefix}{uuid.uuid4().hex[:8]}"


def _unlimited_queue_budget() -> None:
    """In the daemon's process: LimitMSGQUEUE=infinity, as the systemd unit has it, where allowed (the
    user's POSIX-queue budget is shared by every test run on the machine)."""
    import resource

    try:
        resource.setrlimit(resource.RLIMIT_MSGQUEUE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    except (ValueError, OSError):
        pass


class Daemon:
    def __init__(self, tmp_path, scene_text: str, links: list[str], *args: str, env: dict | None = None,
                 runtime: str | None = None, queue_budget_unlimited: bool = False):
        self.tmp = tmp_path
        self.links = links
        self.scene = tmp_path / "scene.yaml"
        self.scene.write_text(scene_text)
        self.runtime = runtime or str(tmp_path / "rt")
        self.trace = tmp_path / "trace.jsonl"
        self.summary = tmp_path / "summary.json"
        self.notify_path = str(tmp_path / "notify.sock")
        self.notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.notify.bind(self.notify_path)
        self.log = open(tmp_path / "daemon.log", "w+")
        environment = dict(os.environ, NOTIFY_SOCKET=self.notify_path, **(env or {}))
        self.process = subprocess.Popen(
            [sys.executable, "-m", "hilgate", "-v", "run", str(self.scene), "--runtime-dir", self.runtime,
             "--trace", str(self.trace), "--summary", str(self.summary), "--no-status-line", *args],
            stdout=self.log, stderr=subprocess.STDOUT, env=environment,
            preexec_fn=_unlimited_queue_budget if queue_budget_unlimited else None)
        self.notifications: list[str] = []

    def wait_for(self, word: str, timeout: float = 20.0) -> list[str]:
        """Wait for a notify datagram containing ``word``; returns its lines."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.notify.settimeout(max(0.01, min(0.5, deadline - time.monotonic())))
            try:
                data = self.notify.recv(4096).decode()
            except socket.timeout:
                if self.process.poll() is not None:
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
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.settimeout(10)
        sock.connect(os.path.join(self.runtime, "control.sock"))
        reader = sock.makefile("r")
        version = json.loads(reader.readline())
        assert version["class"] == "VERSION"
        sock.sendall((json.dumps(request) + "\n").encode())
        reply = json.loads(reader.readline())
        sock.close()
        return reply

    def status(self) -> dict:
        return self.control({"class": "STATUS"})

    def link_status(self, link: str) -> dict:
        return next(l for l in self.status()["links"] if l["id"] == link)

    def wait_clients(self, link: str, count: int = 1, timeout: float = 60.0) -> None:
        """Wait until ``count`` socket clients are attached to ``link``: a client process started just
        before (``hilgate listen``, ``hilgate app``) gets only the frames sent once it is attached, and
        on a loaded host its start-up alone can take seconds.  The bound only guards against a hang."""
        deadline = time.monotonic() + timeout
        while self.link_status(link)["clients"] < count:
            if time.monotonic() > deadline:
                raise AssertionError(f"fewer than {count} clients on {link} after {timeout} s:\n{self.output()}")
            if self.process.poll() is not None:
                raise AssertionError(f"daemon exited with {self.process.returncode}:\n{self.output()}")
            time.sleep(0.05)

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


def peer_events(process: subprocess.Popen, timeout: float = 90.0) -> list[dict]:
    out, _ = process.communicate(timeout=timeout)
    return [json.loads(line) for line in out.splitlines() if line.strip()]
