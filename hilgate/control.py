"""The control socket: line-delimited JSON, every message an object with a ``class`` (as gpsd does).

On connection the daemon announces itself: ``{"class": "VERSION", "release": "0.1.0", "proto": 1}``.
Requests and their replies:

- ``{"class": "STATUS"}`` → ``{"class": "STATUS", "time": t, "scene": name, "links": [...], "vehicles": [...]}``
- ``{"class": "RELOAD"}`` → ``{"class": "RELOAD", "ok": true}`` or ``{"ok": false, "error": "..."}``
- ``{"class": "WATCH", "interval_s": 1.0}`` → a STATUS every interval until ``{"class": "WATCH", "enable": false}``
- anything else → ``{"class": "ERROR", "message": "..."}``
"""

from __future__ import annotations

import json
import logging
import os
from typing import Any, Callable

from . import __version__
from .streams import Connection, Listener, listen_unix

log = logging.getLogger(__name__)

PROTO = 1


class ControlServer:
    def __init__(self, path: str, scheduler: Any, status: Callable[[], dict], reload: Callable[[Callable[[bool, str], Any]], Any],
                 extra: dict[str, Callable[[dict], dict]] | None = None):
        self.path = path
        self.scheduler = scheduler
        self.status = status
        self.reload = reload
        self.extra = extra or {}
        self.clients: set[_ControlClient] = set()
        os.makedirs(os.path.dirname(path), exist_ok=True)
        self.listener = Listener(listen_unix(path), scheduler, self._accept, path)

    def _accept(self, sock) -> None:
        client = _ControlClient(sock, self)
        self.clients.add(client)

    def close(self) -> None:
        for client in list(self.clients):
            client.connection.close()
        self.listener.close()


class _ControlClient:
    MAX_LINE = 65536

    def __init__(self, sock, server: ControlServer):
        self.server = server
        self.buffer = bytearray()
        self.watch = None
        self.connection = Connection(sock, server.scheduler, self._on_data, self._on_close)
        self.send({"class": "VERSION", "release": __version__, "proto": PROTO})

    def send(self, obj: dict) -> None:
        self.connection.write((json.dumps(obj) + "\n").encode())

    def _on_data(self, data: bytes) -> None:
        self.buffer += data
        while b"\n" in self.buffer:
            line, _, rest = bytes(self.buffer).partition(b"\n")
            self.buffer = bytearray(rest)
            if line.strip():
                self.handle(line)
        if len(self.buffer) > self.MAX_LINE:
            self.send({"class": "ERROR", "message": "line too long"})
            self.connection.close()

    def handle(self, line: bytes) -> None:
        try:
            request = json.loads(line)
            kind = request["class"]
        except (ValueError, TypeError, KeyError):
            self.send({"class": "ERROR", "message": "expected a JSON object with a 'class'"})
            return
        server = self.server
        if kind == "STATUS":
            self.send(self._status())
        elif kind == "RELOAD":  # answered when the new scene is applied or refused
            server.reload(lambda ok, error: self.send({"class": "RELOAD", "ok": ok, **({"error": error} if error else {})}))
        elif kind == "WATCH":
            self._stop_watch()
            if request.get("enable", True):
                interval = float(request.get("interval_s", 1.0))
                self._watch(max(0.05, interval))
        elif kind in server.extra:
            self.send(server.extra[kind](request))
        else:
            self.send({"class": "ERROR", "message": f"unknown class {kind!r}"})

    def _status(self) -> dict:
        return {"class": "STATUS", "time": round(self.server.scheduler.now(), 6), **self.server.status()}

    def _watch(self, interval: float) -> None:
        scheduler = self.server.scheduler

        def tick():
            if self.connection.closed:
                return
            self.send(self._status())
            self.watch = scheduler.at(scheduler.now() + interval * scheduler.speed, tick)

        tick()

    def _stop_watch(self) -> None:
        if self.watch is not None:
            self.server.scheduler.cancel(self.watch)
            self.watch = None

    def _on_close(self) -> None:
        self._stop_watch()
        self.server.clients.discard(self)
