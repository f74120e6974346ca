"""Busy neighbours for a test: the topside PC as it is in a lab, with QGroundControl, video, ROS and a
browser beside hilgate.

:class:`Neighbours` starts, beside a test, processes at the test's own priority (the daemon's too: nothing
here is niced): ones that compute without pause (a video encoder), ones that compute 5 ms and rest 1 ms
(a GUI redrawing), and one that writes a file and syncs it (a recorder: ``fdatasync`` stalls whoever
writes to that disk after it).  Each stops by itself after ``limit_s`` (a hang guard, in case the test
process dies without stopping them), and all stop when the test ends.  The test asserts what the modems
do (counts, order, model delays), never how fast anything ran: host load must change none of it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile

HOG = "import time\nend = time.monotonic() + {limit}\nwhile time.monotonic() < end:\n    pass\n"
WAKER = ("import time\nend = time.monotonic() + {limit}\n"
         "while time.monotonic() < end:\n"
         "    t = time.monotonic() + 0.005\n"
         "    while time.monotonic() < t:\n        pass\n"
         "    time.sleep(0.001)\n")
WRITER = ("import os, time\nend = time.monotonic() + {limit}\nblock = os.urandom(1 << 20)\n"
          "while time.monotonic() < end:\n"
          "    with open({path!r}, 'wb') as f:\n"
          "        for _ in range({mib}):\n"
          "            f.write(block)\n"
          "            if time.monotonic() > end:\n                break\n"
          "        os.fdatasync(f.fileno())\n"
          "    os.unlink({path!r})\n")


class Neighbours:
    """``hogs`` CPU-bound processes, ``wakers`` that wake every 6 ms, ``writers`` that write ``mib`` MiB
    and sync, again and again, each for at most ``limit_s`` seconds."""

    def __init__(self, hogs: int = 4, wakers: int = 4, writers: int = 1, mib: int = 256, limit_s: float = 300,
                 directory: str | None = None):
        self.procs: list[subprocess.Popen] = []
        self.directory = tempfile.mkdtemp(prefix="hilgate-load-", dir=directory)
        programs = [HOG.format(limit=limit_s)] * hogs + [WAKER.format(limit=limit_s)] * wakers
        programs += [WRITER.format(limit=limit_s, mib=mib, path=os.path.join(self.directory, f"w{i}"))
                     for i in range(writers)]
        for program in programs:
            self.procs.append(subprocess.Popen([sys.executable, "-c", program], stdin=subprocess.DEVNULL,
                                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                               start_new_session=True))

    def stop(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        for proc in self.procs:
            proc.wait()
        for name in os.listdir(self.directory):
            os.unlink(os.path.join(self.directory, name))
        os.rmdir(self.directory)

    def __enter__(self) -> "Neighbours":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
