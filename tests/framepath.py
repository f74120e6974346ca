"""One frame's path through the real daemon, traced call by call (``python tests/framepath.py`` prints it).

A daemon is built on the two-link ideal scene of ``benchmarks/gli_roundtrip.py`` (real POSIX queues, the
router, the simulated modems) with a scheduler whose ``run`` does passes instead of serving, on a model
clock it sets itself (so nothing depends on the wall clock): the application on link a puts a frame on its
queue, the loop reads it, and the events it causes fire until link b's application has the frame in its
queue.  After warm-up passes (caches, the first READY), one pass is traced with ``sys.setprofile``.

What is counted: Python function calls into hilgate's own code (``hilgate/``, ``models/``, ``drivers/``;
generator expressions and comprehensions are not calls of their own), each with its file.  The frame's
path is every call from the loop reading link a's queue until the frame is in link b's application's
queue (the ``MqEndpoint._put`` that puts it there, included); the READY path is every call after that
until the pass ends with link a's application told READY.
"""

from __future__ import annotations

import os
import sys
import uuid
from dataclasses import dataclass, field

import posix_ipc

from hilgate.core.realtime import RealtimeScheduler
from hilgate.daemon import service
from hilgate.gli.queues import unlink_queues

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PRODUCT = tuple(os.path.join(ROOT, folder) + os.sep for folder in ("hilgate", "models", "drivers"))
ARRIVED, ARRIVED_FROM = "MqEndpoint._put", "MqEndpoint.deliver"  # a received frame goes into a queue
SCENE = """\
name: frame-path
channels: {{ideal: {{speed_mps: 3.0e8}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links:
  {a}: {{vehicle: v, address: 1, bitrate_bps: 1.0e12, fifo_bytes: 10000000, packet: vl2b}}
  {b}: {{vehicle: v, address: 2, bitrate_bps: 1.0e12, fifo_bytes: 10000000, packet: vl2b}}
"""
WARM_UP = 3


@dataclass
class Path:
    calls: list[tuple[str, str]] = field(default_factory=list)  # (file, qualified function), in call order
    arrived: int = 0  # how many calls it took until link b's frame was in its application's queue
    delivered: int = 0  # frames link b's application found in its queue after the pass

    @property
    def frame(self) -> list[tuple[str, str]]:
        """From the loop reading link a's queue until the frame is in link b's application's queue."""
        return self.calls[:self.arrived]

    @property
    def ready(self) -> list[tuple[str, str]]:
        """What follows until link a's application is told READY (its modem done, the announcement)."""
        return self.calls[self.arrived:]

    @staticmethod
    def files(calls: list[tuple[str, str]]) -> list[str]:
        return sorted({file for file, _ in calls})


def _frame(payload: bytes, dst: int) -> bytes:
    """A vl2b frame as a dccomms application writes it: type byte, real packet, virtual area."""
    import binascii
    import struct

    real = b"\x55" + len(payload).to_bytes(2, "big") + payload + binascii.crc_hqx(payload, 0).to_bytes(2, "big")
    return b"\x00" + real.ljust(2053, b"\0") + struct.pack("<III", 1, 0, dst)


def _drain(queue: posix_ipc.MessageQueue) -> int:
    count = 0
    while True:
        try:
            queue.receive(0)
        except posix_ipc.BusyError:
            return count
        count += 1


def _tracer(path: Path):
    stack: list[str] = []  # the qualified names of the Python frames being run

    def profile(frame, event, arg):
        if event == "call":
            code = frame.f_code
            caller = stack[-1] if stack else ""
            stack.append(code.co_qualname)
            if code.co_filename.startswith(PRODUCT) and not code.co_name.startswith("<"):
                path.calls.append((os.path.relpath(code.co_filename, ROOT), code.co_qualname))
                if not path.arrived and code.co_qualname == ARRIVED and caller == ARRIVED_FROM:
                    path.arrived = len(path.calls)
        elif event == "return" and stack:
            stack.pop()

    return profile


def _scheduler(a: str, b: str, path: Path) -> type[RealtimeScheduler]:
    class PassScheduler(RealtimeScheduler):
        clock = 10.0

        def model_time(self) -> float:
            return self.clock

        def one_pass(self, to_a, from_a, from_b, message, traced: bool) -> int:
            self.clock += 1.0
            self.fire_due(self.clock)  # whatever was due before the frame (housekeeping) first
            self.run_deferred()
            self.housekeeping_posted()
            to_a.send(message)
            if traced:
                sys.setprofile(_tracer(path))
            self._handle_inputs(0.0)
            self.fire_due(self.clock + 1e-3)  # the frame's air time and propagation: nanoseconds
            if self._deferred:  # (as the loop does before it waits)
                self.run_deferred()
            if traced:
                sys.setprofile(None)
            _drain(from_a)
            return _drain(from_b)

        def housekeeping_posted(self) -> None:
            """Wall-clock timers that came due late (each pass leaps a second) wait for the inputs ready by
            then (RealtimeScheduler.after_wall): they are housekeeping too, done before the frame."""
            if self.io.posted:
                self._handle_inputs(0.0)  # (as the loop would: the wake-up and the posted calls)

        def run(self, until: float = float("inf")) -> int:
            queues = {name: posix_ipc.MessageQueue(f"/{name}") for name in
                      (f"{a}_tx_dlnk_phy", f"{a}_rx_dlnk_phy", f"{b}_tx_dlnk_phy", f"{b}_rx_dlnk_phy")}
            to_a, from_a = queues[f"{a}_tx_dlnk_phy"], queues[f"{a}_rx_dlnk_phy"]
            to_b, from_b = queues[f"{b}_tx_dlnk_phy"], queues[f"{b}_rx_dlnk_phy"]
            to_b.send(b"\x01")  # REQ_STATE from both applications: both links are attended
            to_a.send(b"\x01")
            self._handle_inputs(0.0)
            self.fire_due(self.clock)
            self.run_deferred()
            message = _frame(b"ping" * 5, 2)
            for _ in range(WARM_UP):
                self.one_pass(to_a, from_a, from_b, message, traced=False)
            path.delivered = self.one_pass(to_a, from_a, from_b, message, traced=True)
            for queue in queues.values():
                queue.close()
            return 0

    return PassScheduler


def trace_one_frame(directory: str) -> Path:
    """The calls of one frame's pass from link a's application to link b's (see the module's words)."""
    token = uuid.uuid4().hex[:8]
    a, b = f"fpa{token}", f"fpb{token}"
    scene = os.path.join(directory, "scene.yaml")
    with open(scene, "w") as handle:
        handle.write(SCENE.format(a=a, b=b))
    path = Path()
    original = service.RealtimeScheduler
    service.RealtimeScheduler = _scheduler(a, b, path)
    try:
        service.Daemon(scene, runtime_dir=os.path.join(directory, "rt")).run()
    finally:
        service.RealtimeScheduler = original
        unlink_queues((a, b))
    return path


@dataclass
class Run:
    """What :func:`run_frames` saw: per pass, the messages link a's application and link b's found in their
    queues (as they read them), and the daemon's trace."""

    to_a: list[list[bytes]] = field(default_factory=list)
    to_b: list[list[bytes]] = field(default_factory=list)
    trace: str = ""


def _take(queue: posix_ipc.MessageQueue) -> list[bytes]:
    taken = []
    while True:
        try:
            taken.append(queue.receive(0)[0])
        except posix_ipc.BusyError:
            return taken


def run_frames(directory: str, passes: int, prepare=None, scene_text: str = SCENE, send=None) -> Run:
    """The real daemon on ``scene_text`` (links ``{a}`` and ``{b}``), on a model clock of its own: both
    applications say REQ_STATE, then each pass a's application sends a frame to address 2 and every event
    it causes fires (a pass as in :func:`trace_one_frame`).  ``prepare(router, a, b)`` runs once the links
    are up, before the applications speak (to attach an endpoint, to take a shortcut away); ``send(router,
    a)``, if given, sends each pass's frame instead of a's application (a frame from no endpoint)."""
    token = uuid.uuid4().hex[:8]
    a, b = f"fra{token}", f"frb{token}"
    scene = os.path.join(directory, "scene.yaml")
    with open(scene, "w") as handle:
        handle.write(scene_text.format(a=a, b=b))
    trace_path = os.path.join(directory, "trace.jsonl")
    run = Run()
    daemon: list[service.Daemon] = []

    class PassScheduler(RealtimeScheduler):
        clock = 10.0

        def model_time(self) -> float:
            return self.clock

        def settle(self) -> None:
            self.fire_due(self.clock + 1e-3)
            if self._deferred:
                self.run_deferred()

        def run(self, until: float = float("inf")) -> int:
            if prepare is not None:
                prepare(daemon[0].router, a, b)
            queues = {name: posix_ipc.MessageQueue(f"/{name}") for name in
                      (f"{a}_tx_dlnk_phy", f"{a}_rx_dlnk_phy", f"{b}_tx_dlnk_phy", f"{b}_rx_dlnk_phy")}
            to_a, from_a = queues[f"{a}_tx_dlnk_phy"], queues[f"{a}_rx_dlnk_phy"]
            to_b, from_b = queues[f"{b}_tx_dlnk_phy"], queues[f"{b}_rx_dlnk_phy"]
            to_b.send(b"\x01")
            to_a.send(b"\x01")
            self._handle_inputs(0.0)
            self.settle()
            run.to_a.append(_take(from_a))
            run.to_b.append(_take(from_b))
            message = _frame(b"ping" * 5, 2)
            for _ in range(passes):
                self.clock += 1.0
                self.settle()
                if send is None:
                    to_a.send(message)
                    self._handle_inputs(0.0)
                else:
                    send(daemon[0].router, a)
                self.settle()
                run.to_a.append(_take(from_a))
                run.to_b.append(_take(from_b))
            for queue in queues.values():
                queue.close()
            return 0

    original = service.RealtimeScheduler
    service.RealtimeScheduler = PassScheduler
    try:
        daemon.append(service.Daemon(scene, runtime_dir=os.path.join(directory, "rt"), trace_path=trace_path))
        daemon[0].run()
    finally:
        service.RealtimeScheduler = original
        unlink_queues((a, b))
    with open(trace_path) as handle:
        run.trace = handle.read()
    return run


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory(prefix="hilgate-path-") as scratch:  # nothing left in $TMPDIR
        traced = trace_one_frame(scratch)
    for title, calls in (("frame", traced.frame), ("READY", traced.ready)):
        print(f"{title}: {len(calls)} calls in {len(Path.files(calls))} files")
        for number, (file, name) in enumerate(calls, 1):
            print(f"  {number:3d} {file}: {name}")
    print(f"delivered: {traced.delivered}")
