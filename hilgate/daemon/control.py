"""The control socket: line-delimited JSON, every message an object with a ``class`` (as gpsd does).

On connection the daemon announces itself: ``{"class": "VERSION", "release": "0.1.0", "proto": 1}``.
Requests and their replies:

- ``{"class": "STATUS"}`` → ``{"class": "STATUS", "time": t, "scene": name, "links": [...], "vehicles": [...]}``
- ``{"class": "RELOAD"}`` → ``{"class": "RELOAD", "ok": true}`` or ``{"ok": false, "error": "..."}``
- ``{"class": "NETWORK"}`` (a daemon of several hosts) → ``{"class": "NETWORK", "hosts": [...]}``: every
  daemon's status as it answered over Zenoh
- ``{"class": "WATCH", "interval_s": 1.0}`` → a STATUS at once and every interval until
  ``{"class": "WATCH", "enable": false}``, which is answered ``{"class": "WATCH", "enable": false}``
- anything else, or a request with bad values → ``{"class": "ERROR", "error": "..."}``

Everything a client sends is checked: a line is at most 16 KB of JSON nested at most 32 deep, the
``class`` is a string, every value has its type.  At most ``max_clients`` are connected at once (the
next is told so and closed), and one that stops reading is disconnected once 256 KB of replies wait
for it.  None of this costs another client, a link or the loop anything.
"""

from __future__ import annotations

import json
import logging
import math
import os
from typing import Any, Callable

from .. import __version__
from ..core import safejson
from ..core.streams import Connection, Listener, listen_unix, refuse

log = logging.getLogger(__name__)

PROTO = 1


MAX_CLIENTS = 32
"""Control connections at once: enough for every operator tool, few enough to bound memory."""

OUTPUT_CAP = 256 * 1024
"""Bytes of replies kept for one control client that does not read; past it, it is disconnected."""

MIN_WATCH_S, MAX_WATCH_S = 0.05, 3600.0


class RequestError(ValueError):
    """A request the daemon understands the shape of, but not these values."""


class ControlServer:
    def __init__(self, path: str, scheduler: Any, status: Callable[[], dict],
                 reload: Callable[[Callable[[bool, str], Any]], Any],
                 extra: dict[str, Callable[[dict], dict]] | None = None, max_clients: int = MAX_CLIENTS,
                 group: int | None = None,
                 deferred: dict[str, Callable[[dict, Callable[[dict], Any]], Any]] | None = None):
        self.path = path
        self.scheduler = scheduler
        self.status = status
        self.reload = reload
        self.extra = extra or {}
        self.deferred = deferred or {}  # requests answered later, through the callback they are given
        self.max_clients = max_clients
        self.clients: set[_ControlClient] = set()
        os.makedirs(os.path.dirname(path), exist_ok=True)
        self.listener = Listener(listen_unix(path, group=group), scheduler, self._accept, path)

    def _accept(self, sock) -> None:
        if len(self.clients) >= self.max_clients:
            log.info("control client refused: %d connected already", len(self.clients))
            refuse(sock, (json.dumps({"class": "ERROR", "error": f"too many control clients ({self.max_clients})"})
                          + "\n").encode())
            return
        client = _ControlClient(sock, self)
        self.clients.add(client)

    def close(self) -> None:
        for client in list(self.clients):
            client.connection.close()
        self.listener.close()


class _ControlClient:
    MAX_LINE = 16384

    def __init__(self, sock, server: ControlServer):
        self.server = server
        self.buffer = bytearray()
        self.watch = None
        self.connection = Connection(sock, server.scheduler, self._on_data, self._on_close, max_buffer=OUTPUT_CAP)
        self.send({"class": "VERSION", "release": __version__, "proto": PROTO})

    def send(self, obj: dict) -> None:
        if not self.connection.write((json.dumps(obj) + "\n").encode()) and not self.connection.closed:
            # it stopped reading (a WATCH nobody consumes): it would only cost memory
            log.info("control client stopped reading; disconnected")
            self.connection.close()

    def _on_data(self, data: bytes) -> None:
        self.buffer += data
        while not self.connection.closed:
            end = self.buffer.find(b"\n")
            if end < 0:
                break
            line = bytes(self.buffer[:end])
            del self.buffer[: end + 1]
            if len(line) > self.MAX_LINE:
                self._too_long()
                return
            if line.strip():
                self.handle(line)
        if len(self.buffer) > self.MAX_LINE:
            self._too_long()

    def _too_long(self) -> None:
        self.send({"class": "ERROR", "error": f"line longer than {self.MAX_LINE} bytes"})
        self.connection.close()

    def handle(self, line: bytes) -> None:
        try:
            request = safejson.loads(line, max_bytes=self.MAX_LINE)
        except safejson.JsonError as exc:
            self.send({"class": "ERROR", "error": f"expected a JSON object with a 'class': {exc}"})
            return
        kind = request.get("class") if isinstance(request, dict) else None
        if not isinstance(kind, str):
            self.send({"class": "ERROR", "error": "expected a JSON object with a 'class' (a string)"})
            return
        try:
            self._dispatch(kind, request)
        except RequestError as exc:
            self.send({"class": "ERROR", "error": f"{kind}: {exc}"})
        except Exception as exc:  # a bug must cost one answer, not the client or the daemon
            log.error("control request %s failed: %s: %s", kind[:40], type(exc).__name__, exc)
            self.send({"class": "ERROR", "error": f"{kind}: internal error: {type(exc).__name__}"})

    def _dispatch(self, kind: str, request: dict) -> None:
        server = self.server
        if kind == "STATUS":
            self.send(self._status())
        elif kind == "RELOAD":  # answered when the new scene is applied or refused
            server.reload(lambda ok, error: self.send({"class": "RELOAD", "ok": ok, **({"error": error} if error else {})}))
        elif kind == "WATCH":
            enable = request.get("enable", True)
            if not isinstance(enable, bool):
                raise RequestError("enable must be true or false")
            interval = request.get("interval_s", 1.0)
            if enable and (isinstance(interval, bool) or not isinstance(interval, (int, float))
                           or not math.isfinite(interval)):
                raise RequestError(f"interval_s must be a number of seconds, not {json.dumps(interval)[:40]}")
            self._stop_watch()
            if enable:
                self._watch(min(MAX_WATCH_S, max(MIN_WATCH_S, float(interval))))  # answered by its first STATUS
            else:
                self.send({"class": "WATCH", "enable": False})
        elif kind in server.extra:
            self.send(server.extra[kind](request))
        elif kind in server.deferred:
            server.deferred[kind](request, self.send)
        else:
            self.send({"class": "ERROR", "error": f"unknown class {kind[:40]!r}"})

    def _status(self) -> dict:
        return {"class": "STATUS", "time": round(self.server.scheduler.now(), 6), **self.server.status()}

    def _watch(self, interval: float) -> None:
        scheduler = self.server.scheduler

        def tick():
            if self.connection.closed:
                return
            self.send(self._status())
            self.watch = scheduler.after_wall(interval, tick)

        tick()

    def _stop_watch(self) -> None:
        if self.watch is not None:
            self.server.scheduler.cancel(self.watch)
            self.watch = None

    def _on_close(self) -> None:
        self._stop_watch()
        self.server.clients.discard(self)
