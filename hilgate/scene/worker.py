"""Loading a scene for a reload in a child process, so that the scene file costs the loop nothing.

A reload re-reads a file that anyone allowed to edit it may have made hostile or merely huge.  Parsed
on the real-time loop, a 10 MB scene stopped every delivery for 11 s.  Here the daemon starts
``python -m hilgate.scene.worker``, which limits its own memory and CPU time, loads and validates the
scene exactly as ``hilgate check`` does, and writes back one message on stdout:

    b"S" + pickle of the Scene       the scene is valid
    b"E" + UTF-8 one-line message    it is not (or the worker ran out of its budget)

The daemon reads it through its loop without blocking (:class:`SceneJob`), unpickles only hilgate's
own classes (:func:`load_result`), and applies the scene on the loop.  A worker that dies, exceeds its
budget or takes longer than ``timeout_s`` is a refused reload, never a stalled daemon.
"""

from __future__ import annotations

import io
import json
import logging
import os
import pickle
import resource
import signal
import subprocess
import sys
from typing import Any, Callable

log = logging.getLogger(__name__)

MEMORY_LIMIT = 1 << 30  # address space of the worker: PyYAML on a 1 MB scene needs far less
CPU_LIMIT_S = 30
MAX_RESULT = 64 << 20


def request_for(path: str, overrides: list[str], **options: Any) -> dict[str, Any]:
    return {"path": path, "overrides": list(overrides), "options": options}


def _limit_self() -> None:
    for limit, value in ((resource.RLIMIT_AS, MEMORY_LIMIT), (resource.RLIMIT_CPU, CPU_LIMIT_S)):
        try:
            soft, hard = resource.getrlimit(limit)
            wanted = value if hard == resource.RLIM_INFINITY else min(value, hard)
            resource.setrlimit(limit, (wanted, hard))
        except (ValueError, OSError):
            pass


def work(request: dict[str, Any]) -> bytes:
    """What the worker writes for one request (also callable in-process, for tests)."""
    from .yaml_nodes import SceneError
    from .load import load_scene

    try:
        scene = load_scene(request["path"], request.get("overrides", []), **request.get("options", {}))
        return b"S" + pickle.dumps(scene, protocol=pickle.HIGHEST_PROTOCOL)
    except SceneError as exc:
        return b"E" + _one_line(str(exc)).encode()
    except MemoryError:
        return b"E" + _one_line(f"{request['path']}: the scene needs more than "
                                f"{MEMORY_LIMIT >> 20} MB to load").encode()
    except RecursionError:
        return b"E" + _one_line(f"{request['path']}: the scene is nested too deeply").encode()
    except Exception as exc:  # anything else is still a refused reload, said in one line
        return b"E" + _one_line(f"{request['path']}: cannot load: {type(exc).__name__}: {exc}").encode()


def _one_line(text: str, limit: int = 500) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def main() -> int:
    _limit_self()
    request = json.loads(sys.stdin.buffer.read(1 << 20))
    sys.stdout.buffer.write(work(request))
    sys.stdout.buffer.flush()
    return 0


class _HilgateOnly(pickle.Unpickler):
    """Only hilgate's own scene classes and plain builtins come back from the worker."""

    SAFE_BUILTINS = {"set", "frozenset", "dict", "list", "tuple", "float", "int", "str", "bool", "complex"}

    def find_class(self, module: str, name: str) -> Any:
        if module == "hilgate" or module.startswith("hilgate."):
            return super().find_class(module, name)
        if module == "builtins" and name in self.SAFE_BUILTINS:
            return super().find_class(module, name)
        if module == "copyreg" and name == "_reconstructor":
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"the scene worker sent {module}.{name}")


def load_result(data: bytes) -> tuple[Any, str | None]:
    """(scene, None) or (None, error) from what the worker wrote."""
    if data[:1] == b"S":
        try:
            return _HilgateOnly(io.BytesIO(data[1:])).load(), None
        except Exception as exc:
            return None, f"the scene worker's answer is unreadable: {type(exc).__name__}: {exc}"
    if data[:1] == b"E":
        return None, data[1:].decode("utf-8", "replace")
    return None, "the scene worker ended without an answer"


class SceneJob:
    """One scene load in a worker process, watched from the real-time loop without blocking.

    ``on_done(scene, error)`` is called once, in the loop: with the scene, or with None and a one-line
    reason (invalid scene, worker crashed, out of budget, timed out)."""

    def __init__(self, scheduler: Any, request: dict[str, Any], on_done: Callable[[Any, str | None], Any],
                 timeout_s: float = 60.0):
        self.scheduler = scheduler
        self.on_done = on_done
        self.data = bytearray()
        self.done = False
        self.process = subprocess.Popen(
            [sys.executable, "-m", "hilgate.scene.worker"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL, close_fds=True, start_new_session=True)
        try:
            self.process.stdin.write(json.dumps(request).encode())
            self.process.stdin.close()
        except OSError:
            pass
        self.fd = self.process.stdout.fileno()
        os.set_blocking(self.fd, False)
        scheduler.add_reader(self.fd, self._readable)
        self.timer = scheduler.after_wall(timeout_s, self._timeout, timeout_s)

    def _readable(self) -> None:
        try:
            chunk = os.read(self.fd, 1 << 20)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._finish(None, f"reading the scene worker failed: {exc}")
            return
        if chunk:
            self.data += chunk
            if len(self.data) > MAX_RESULT:
                self._finish(None, "the scene worker's answer is too large")
            return
        self._finish(*load_result(bytes(self.data)))

    def _timeout(self, timeout_s: float) -> None:
        self._finish(None, f"loading the scene took longer than {timeout_s:g} s")

    def _finish(self, scene: Any, error: str | None) -> None:
        if self.done:
            return
        self.done = True
        self.scheduler.cancel(self.timer)
        self.scheduler.remove_reader(self.fd)
        self.process.stdout.close()
        if self.process.poll() is None:
            try:
                self.process.send_signal(signal.SIGKILL)
            except OSError:
                pass
        self.scheduler.post(self._reap)
        self.on_done(scene, error)

    def _reap(self) -> None:
        """Collect the worker (it has exited or been killed) without waiting on the loop for long."""
        if self.process.poll() is None:
            self.scheduler.after_wall(0.05, self._reap)

    def cancel(self) -> None:
        self._finish(None, "cancelled")


if __name__ == "__main__":
    sys.exit(main())
