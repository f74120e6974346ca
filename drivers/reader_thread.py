"""A live source's reader: a thread of its own (a camera's frames, a MAVLink connection) that blocks on its
device, not on the real-time loop, and hands what it reads to the loop through a thread-safe callback.
It runs ``_run`` until it is stopped; ``_run`` checks ``_stop`` between reads."""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod


class ReaderThread(ABC):
    def __init__(self, thread_name: str):
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    @abstractmethod
    def _run(self) -> None:
        """Read the device until ``_stop`` is set."""
