#!/usr/bin/env python3
"""The CPU cost of one daemon pass, in process: a frame an application put on link a's POSIX queue,
read by the loop and carried through the GLI, the router and the simulated modems to link b's queue.

The round-trip benchmarks measure passes plus wake-ups of sleeping processes plus the applications;
this one isolates the daemon's own work (Python and its system calls), which is what a faster hot
path (docs/compiled-hot-path.md) or a leaner per-frame path would change.  A real daemon is built on
``gli_roundtrip.py``'s two-link ideal scene; its scheduler's ``run`` is replaced (in a subclass) by a
loop that puts one frame on a's queue, times one pass, and empties the applications' queues.

Run from the repository root:

    python benchmarks/pass_cost.py [PASSES]          # p10 / p50 / p90 of PASSES passes (default 20 000)
    PROF=1 python benchmarks/pass_cost.py 3000       # and a cProfile table of the passes
    python benchmarks/pass_instructions.py           # instructions per pass, counted by callgrind

Under callgrind (``pass_instructions.py`` sets ``PASS_COST_CALLGRIND``) only the passes themselves are
counted, after ``CALLGRIND_WARM_UP`` passes: collection is switched on and off around each one, so the
harness's own ``send`` and drains are left out; the daemon's passes and the relay's are dumped apart.

It runs pinned to the first CPU it may use (``placement.py``) and says so: one process, so one placement.
Then the same for the bare Python relay of ``gli_roundtrip.py`` (its pass written out here: ``epoll``, the
message taken, its vl2b CRC checked, the frame into b's queue and READY into a's): the least a pass of
any Python daemon costs on this machine, measured in the same run.
"""

from __future__ import annotations

import cProfile
import gc
import os
import pstats
import shutil
import sys
import tempfile
import time

import binascii
import ctypes
import select
import subprocess

import posix_ipc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gli_roundtrip import READY_MESSAGE, SCENE, frame, open_queue  # noqa: E402
from placement import pin  # noqa: E402

from hilgate.core.realtime import RealtimeScheduler  # noqa: E402
from hilgate.daemon import service  # noqa: E402
from hilgate.gli.queues import unlink_queues  # noqa: E402


CALLGRIND_WARM_UP = 200
CALLGRIND_C = """#include <valgrind/callgrind.h>
void hg_start(void) { CALLGRIND_START_INSTRUMENTATION; }
void hg_toggle(void) { CALLGRIND_TOGGLE_COLLECT; }
void hg_dump(const char *what) { CALLGRIND_DUMP_STATS_AT(what); }
"""


class Counting:
    """Callgrind's collection switched on around each pass after the warm-up (a no-op outside callgrind:
    ``PASS_COST_CALLGRIND`` unset).  The client requests are C macros: a small library is compiled for them."""

    def __init__(self) -> None:
        self.lib = None
        if os.environ.get("PASS_COST_CALLGRIND"):
            directory = tempfile.mkdtemp(prefix="hilgate-callgrind-")
            source, library = os.path.join(directory, "toggle.c"), os.path.join(directory, "toggle.so")
            with open(source, "w") as handle:
                handle.write(CALLGRIND_C)
            try:
                subprocess.run(["cc", "-O1", "-shared", "-fPIC", "-o", library, source], check=True)
                self.lib = ctypes.CDLL(library)  # (loaded: the files can go, it stays mapped)
            finally:
                shutil.rmtree(directory, ignore_errors=True)
            # (pass_instructions.py starts callgrind with instrumentation off: Python's start-up and the
            # imports run several times faster uninstrumented, and nothing before the passes is counted)
            self.lib.hg_start()

    def toggle(self, index: int) -> None:
        if self.lib is not None and index >= CALLGRIND_WARM_UP:
            self.lib.hg_toggle()

    def dump(self, what: str) -> None:
        if self.lib is not None:
            self.lib.hg_dump(what.encode())


COUNTING = Counting()


def _drain(queue: posix_ipc.MessageQueue) -> int:
    """Empty an application's queue as its application would; how many messages were there."""
    count = 0
    while True:
        try:
            queue.receive(0)
        except posix_ipc.BusyError:
            return count
        count += 1


def measuring_scheduler(a: str, b: str, passes: int, profile: bool, pinned_cpu: int) -> type[RealtimeScheduler]:
    """A scheduler whose ``run`` times ``passes`` passes instead of serving (a subclass: a class
    compiled by mypyc cannot be patched)."""

    class PassScheduler(RealtimeScheduler):
        def run(self, until: float = float("inf")) -> int:
            self.start_clock()
            gc.disable()
            queues = {name: posix_ipc.MessageQueue(f"/{name}") for name in
                      (f"{a}_tx_dlnk_phy", f"{a}_rx_dlnk_phy", f"{b}_tx_dlnk_phy", f"{b}_rx_dlnk_phy")}
            to_a, from_a = queues[f"{a}_tx_dlnk_phy"], queues[f"{a}_rx_dlnk_phy"]
            to_b, from_b = queues[f"{b}_tx_dlnk_phy"], queues[f"{b}_rx_dlnk_phy"]
            to_b.send(b"\x01")  # REQ_STATE from both applications: both links are attended
            to_a.send(b"\x01")
            self._handle_inputs(0.0)
            self.fire_due(self.model_time())
            _drain(from_a)
            _drain(from_b)
            message = frame(b"ping" * 5, 0, 2)
            profiler = cProfile.Profile(time.thread_time) if profile else None  # CPU time: a loaded host does not skew it
            samples, states, frames, cpu = [], 0, 0, 0.0
            for index in range(passes):
                to_a.send(message)
                cpu_started = time.thread_time()
                started = time.perf_counter()
                if profiler:
                    profiler.enable()
                COUNTING.toggle(index)
                self._handle_inputs(0.0)
                while self.peek() <= self.model_time():
                    self.fire_due(self.model_time())
                if self._deferred:
                    self.run_deferred()
                COUNTING.toggle(index)
                if profiler:
                    profiler.disable()
                samples.append(time.perf_counter() - started)
                cpu += time.thread_time() - cpu_started
                states += _drain(from_a)
                frames += _drain(from_b)
            COUNTING.dump("daemon")
            samples.sort()
            print(f"one daemon pass (a's queue -> b's queue, in process, pinned to CPU {pinned_cpu}), {passes:,} passes: "
                  f"p10 {samples[passes // 10] * 1e6:.1f} µs, p50 {samples[passes // 2] * 1e6:.1f} µs, "
                  f"p90 {samples[9 * passes // 10] * 1e6:.1f} µs, CPU (thread time) {cpu / passes * 1e6:.1f} µs a pass on average; READY messages per frame {states / passes:.2f}, "
                  f"frames delivered {frames:,}", flush=True)
            if profiler:
                pstats.Stats(profiler).sort_stats("tottime").print_stats(40)
            for queue in queues.values():
                queue.close()
            return 0

    return PassScheduler


def relay_passes(passes: int, pinned_cpu: int) -> None:
    """The bare Python relay's pass (``gli_roundtrip._relay``'s, step for step), timed as the daemon's is."""
    tag = f"/pr{os.getpid()}"
    names = [f"{tag}{link}_{way}" for link in "ab" for way in ("tx", "rx")]
    queues = [open_queue(name) for name in names]
    a_tx, a_rx, b_tx, b_rx = queues
    route = {a_tx.mqd: (a_tx, b_rx, a_rx), b_tx.mqd: (b_tx, a_rx, b_rx)}
    epoll = select.epoll()
    for fd in route:
        epoll.register(fd, select.EPOLLIN)
    message = frame(b"ping" * 5, 0, 2)
    samples, cpu = [], 0.0
    gc.disable()
    try:
        for index in range(passes):
            a_tx.send(message)
            cpu_started = time.thread_time()
            started = time.perf_counter()
            COUNTING.toggle(index)
            for fd, _events in epoll.poll(0):
                source, target, sender = route[fd]
                got, _ = source.receive(0)
                if got[0] == 0:
                    end = 4 + int.from_bytes(got[2:4], "big")
                    if binascii.crc_hqx(got[4:end], 0) == int.from_bytes(got[end:end + 2], "big"):
                        target.send(got)
                        sender.send(READY_MESSAGE)
            COUNTING.toggle(index)
            samples.append(time.perf_counter() - started)
            cpu += time.thread_time() - cpu_started
            _drain(a_rx)
            _drain(b_rx)
        COUNTING.dump("relay")
    finally:
        gc.enable()
        epoll.close()
        for queue, name in zip(queues, names):
            queue.close()
            posix_ipc.unlink_message_queue(name)
    samples.sort()
    print(f"one bare Python relay pass (the same frame, the same queues' work, pinned to CPU {pinned_cpu}), {passes:,} passes: "
          f"p10 {samples[passes // 10] * 1e6:.1f} µs, p50 {samples[passes // 2] * 1e6:.1f} µs, "
          f"p90 {samples[9 * passes // 10] * 1e6:.1f} µs, CPU (thread time) {cpu / passes * 1e6:.1f} µs a pass on average",
          flush=True)


def main() -> int:
    passes = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    cpu = min(os.sched_getaffinity(0))
    pin(cpu)  # before the daemon makes any thread
    a, b = f"ppa{os.getpid()}", f"ppb{os.getpid()}"
    directory = tempfile.mkdtemp(prefix="hilgate-pass-")
    scene = os.path.join(directory, "scene.yaml")
    with open(scene, "w") as handle:
        handle.write(SCENE.format(a=a, b=b))
    service.RealtimeScheduler = measuring_scheduler(a, b, passes, bool(os.environ.get("PROF")), cpu)
    try:
        status = service.Daemon(scene, runtime_dir=os.path.join(directory, "rt")).run()
    finally:
        unlink_queues((a, b))
        shutil.rmtree(directory, ignore_errors=True)  # (every make test runs this: nothing left in /tmp)
    relay_passes(passes, cpu)
    return status


if __name__ == "__main__":
    sys.exit(main())
