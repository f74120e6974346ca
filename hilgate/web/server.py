"""The web door: one page, its scripts, and a WebSocket that pushes the pictures, from a thread of its own.

**Why tornado.**  One mature package (maintained since 2009, pure Python, no dependencies of its own)
that has the HTTP server, static files with caching headers and the WebSocket protocol (RFC 6455,
pings, message size limits) together, on asyncio; it runs in a thread beside the daemon without asking
anything of the daemon's loop.  aiohttp does the same with seven dependencies; the ``websockets``
package serves no files; uvicorn/starlette are two packages and an ASGI layer for one page.

**The daemon's loop never waits for a browser.**  The loop hands a picture over with :meth:`publish`
(it keeps only the latest, and wakes the server's thread through tornado's own wake-up descriptor,
which never blocks); the server's thread encodes it once and writes it to every page whose last
picture has gone out.  A page that does not read gets no new picture until it does: at most one per
page waits in memory.  Nothing of the daemon's state is read here: pictures are plain data.

**The same access rules as the other doors.**  Loopback unless an address is given.  The page and its
scripts are public (no secret in them); the WebSocket gives nothing before the page proves that it
holds the daemon's token (the TCP GLI's file, readable by the daemon's group) by the TCP GLI's own
challenge: a fresh nonce, answered with HMAC-SHA256(token, nonce), so the token never crosses the
network.  The page gets the token once, from the address's fragment (``#token=…``, which browsers never
send to a server) or typed in, and keeps it for the tab only (sessionStorage).  WebSockets from pages
of other origins are refused (a web site the operator visits cannot even start the challenge), and at
most ``max_pages`` pages and ``MAX_CONNECTIONS`` connections are served at once; one that has not
proved the token within ``AUTH_TIMEOUT_S`` is closed.
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
import logging
import os
import threading
import time
from typing import Any, Callable

__all__ = ["MissingTornado", "WebServer", "parse_web", "MAX_PAGES"]

log = logging.getLogger(__name__)

STATIC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "static")
MAX_PAGES = 8
MAX_CONNECTIONS = 64
AUTH_TIMEOUT_S = 20.0
MAX_MESSAGE = 4096
"""A page's messages are a proof or a player command: tens of bytes."""
REPLAY_TICK_S = 0.05
"""The trace player's pictures: 20 a second."""
MISSING = ("the web view needs tornado, an optional extra: pip install 'hilgate[web]' (or pip install tornado)")


class MissingTornado(OSError):
    """tornado is not installed; the message says how to install it (an OSError: the command's one-line
    error, as for a port in use)."""


def parse_web(value: str) -> tuple[str, int]:
    """``PORT`` or ``ADDR:PORT`` (``[::1]:PORT`` for IPv6); loopback unless an address is given; port 0:
    any free port (the start line and ``hilgate status`` say which).  ValueError says what is wrong."""
    host, _, port = str(value).rpartition(":")
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"{value!r} is not [ADDR:]PORT with a port from 0 to 65535")
    host = host.strip("[]") or "127.0.0.1"
    return host, int(port)


def url_of(host: str, port: int) -> str:
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return f"http://{host}:{port}/"
    if address.is_unspecified:  # 0.0.0.0 / ::: every interface; this host's loopback shows it here
        return f"http://{'[::1]' if address.version == 6 else '127.0.0.1'}:{port}/"
    return f"http://[{host}]:{port}/" if address.version == 6 else f"http://{host}:{port}/"


def _tornado():
    try:
        import tornado.httpserver
        import tornado.ioloop
        import tornado.netutil
        import tornado.web
        import tornado.websocket
    except ImportError:
        raise MissingTornado(MISSING) from None
    return tornado


class WebServer:
    """The page and its WebSocket on ``host:port``.  ``check``: the token's challenge (``challenge()``,
    ``verify(nonce, proof)``); ``replay``: a :class:`hilgate.web.replay.Replay` to play (else the
    pictures come from :meth:`publish`)."""

    def __init__(self, host: str, port: int, check: Any, replay: Any = None, max_pages: int = MAX_PAGES,
                 token_hint: str = ""):
        tornado = _tornado()
        self.check = check
        self.replay = replay
        self.mode = "live" if replay is None else "replay"
        self.max_pages = max_pages
        self.token_hint = token_hint
        self.pages: set[Any] = set()          # authenticated WebSockets (the server's thread only)
        self.connections: set[Any] = set()    # every WebSocket, authenticated or not
        self.clients = 0
        """Authenticated pages now: read by the daemon's loop (an int, set by the server's thread)."""
        self._scene: dict[str, Any] | None = None
        self._state: dict[str, Any] | None = None
        self._scene_text: str | None = None
        self._state_text: str | None = None
        self._scheduled = False
        self._scene_new = False
        self._ioloop: Any = None
        self._thread: threading.Thread | None = None
        self._stopped: asyncio.Event | None = None
        self._ready = threading.Event()
        # bound here, on the caller's thread: a port in use refuses the start in one line
        self.sockets = tornado.netutil.bind_sockets(port, host, reuse_port=False)
        bound = self.sockets[0].getsockname()
        self.host, self.port = host, bound[1]
        self.url = url_of(host, self.port)

    # -- the daemon's side (any thread) ---------------------------------------------------------

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="web", daemon=True)
        self._thread.start()
        self._ready.wait(30)

    def publish(self, scene: dict[str, Any] | None, state: dict[str, Any]) -> None:
        """Hand the server the latest picture (and a new scene, when it changed); never blocks.  The
        dictionaries are the server's from now on: the caller must not change them."""
        if scene is not None:
            self._scene = scene
            self._scene_new = True
        self._state = state
        if not self._scheduled and self._ioloop is not None:
            self._scheduled = True
            self._ioloop.add_callback(self._fan_out)

    def close(self) -> None:
        if self._ioloop is not None and self._thread is not None:
            self._ioloop.add_callback(self._stop)
            self._thread.join(10)
        for sock in self.sockets:
            try:
                sock.close()
            except OSError:
                pass

    # -- the server's thread ----------------------------------------------------------------------

    def _run(self) -> None:
        try:
            asyncio.run(self._serve())
        except Exception:  # the daemon goes on without its web view, and says so
            log.exception("the web view stopped")
        finally:
            self._ready.set()

    async def _serve(self) -> None:
        tornado = _tornado()
        self._stopped = asyncio.Event()
        self._ioloop = tornado.ioloop.IOLoop.current()
        app = tornado.web.Application(_handlers(self, tornado), websocket_max_message_size=MAX_MESSAGE,
                                      websocket_ping_interval=10, websocket_ping_timeout=30,
                                      compress_response=False)
        server = _bounded_server(tornado)(app, idle_connection_timeout=60, body_timeout=10,
                                          max_header_size=16384, max_body_size=MAX_MESSAGE)
        server.add_sockets(self.sockets)
        self._ready.set()
        await self._stopped.wait()
        server.stop()
        for page in list(self.connections):
            page.close(1001, "the daemon stops")

    def _stop(self) -> None:
        if self._stopped is not None:
            self._stopped.set()

    def _fan_out(self) -> None:
        self._scheduled = False  # first: a picture published from now on schedules another round
        scene_changed, self._scene_new = self._scene_new, False
        state = self._state
        if scene_changed or self._scene_text is None:
            self._scene_text = json.dumps(self._scene) if self._scene is not None else None
            for page in list(self.pages):
                page.send_text(self._scene_text, force=True)
        if state is None:
            return
        self._state_text = text = json.dumps(state)
        for page in list(self.pages):
            page.send_text(text)

    def _welcome(self, page: Any) -> bool:
        if len(self.pages) >= self.max_pages:
            return False
        self.pages.add(page)
        self.clients = len(self.pages)
        log.info("web view: a page connected from %s (%d now)", page.peer, self.clients)
        if self.replay is None:
            if self._scene is not None:
                page.send_text(self._scene_text or json.dumps(self._scene), force=True)
            if self._state_text is not None:
                page.send_text(self._state_text)
        return True

    def _gone(self, page: Any) -> None:
        self.connections.discard(page)
        if page in self.pages:
            self.pages.discard(page)
            self.clients = len(self.pages)
            log.info("web view: a page left (%d now)", self.clients)


def _bounded_server(tornado: Any) -> Any:
    class BoundedServer(tornado.httpserver.HTTPServer):
        """At most ``MAX_CONNECTIONS`` connections at once: the next is closed at once."""

        streams: set = set()

        def handle_stream(self, stream: Any, address: Any) -> None:
            self.streams = {s for s in self.streams if not s.closed()}
            if len(self.streams) >= MAX_CONNECTIONS:
                stream.close()
                return
            self.streams.add(stream)
            super().handle_stream(stream, address)

    return BoundedServer


def _handlers(server: WebServer, tornado: Any) -> list:
    web = tornado.web

    def harden(handler: Any) -> None:
        handler.set_header("X-Content-Type-Options", "nosniff")
        handler.set_header("X-Frame-Options", "DENY")
        handler.set_header("Referrer-Policy", "no-referrer")
        handler.set_header("Content-Security-Policy",
                           "default-src 'self'; connect-src 'self'; img-src 'self' data:; "
                           "style-src 'self'; script-src 'self'; frame-ancestors 'none'")

    class Page(web.RequestHandler):
        def set_default_headers(self) -> None:
            harden(self)
            self.set_header("Cache-Control", "no-store")

        def get(self) -> None:
            with open(os.path.join(STATIC, "index.html"), "rb") as handle:
                self.set_header("Content-Type", "text/html; charset=utf-8")
                self.write(handle.read())

    class Static(web.StaticFileHandler):
        def set_default_headers(self) -> None:
            harden(self)

    class Socket(tornado.websocket.WebSocketHandler):
        """One page: HELLO with a nonce, its AUTH, then pictures (and, for a trace, its player's commands)."""

        def open(self) -> None:
            self.peer = self.request.remote_ip
            self.nonce = server.check.challenge()
            self.authed = False
            self.pending: Any = None   # the last picture's write, while it has not gone out
            self.behind = False
            self.player: Any = None
            server.connections.add(self)
            if len(server.connections) > MAX_CONNECTIONS:
                self.close(1013, "too many connections")
                return
            self.send_json({"class": "HELLO", "mode": server.mode, "nonce": self.nonce.hex(),
                            "token_hint": server.token_hint})
            self.timeout = tornado.ioloop.IOLoop.current().call_later(AUTH_TIMEOUT_S, self._too_slow)

        def _too_slow(self) -> None:
            if not self.authed:
                self.close(1008, "no proof of the token")

        def send_json(self, obj: dict) -> None:
            self.send_text(json.dumps(obj), force=True)

        def send_text(self, text: str, force: bool = False) -> None:
            """A picture goes only when the last one has gone out (``force``: scenes, answers)."""
            if self.ws_connection is None or self.ws_connection.is_closing():
                return
            if not force and self.pending is not None and not self.pending.done():
                self.behind = True
                return
            try:
                self.pending = self.write_message(text)
            except tornado.websocket.WebSocketClosedError:
                pass

        def on_message(self, message: Any) -> None:
            try:
                request = json.loads(message)
            except (ValueError, RecursionError):
                request = None
            kind = request.get("class") if isinstance(request, dict) else None
            if not self.authed:
                if kind != "AUTH" or not server.check.verify(self.nonce, request.get("proof")):
                    log.warning("web view: a page from %s did not prove the token; closed", self.peer)
                    self.send_json({"class": "ERROR", "error": "the token's proof is wrong: give the token of "
                                                               + (server.token_hint or "the daemon")})
                    self.close(1008, "wrong proof")
                    return
                self.authed = True
                tornado.ioloop.IOLoop.current().remove_timeout(self.timeout)
                if not server._welcome(self):
                    self.send_json({"class": "ERROR", "error": f"too many pages at once ({server.max_pages})"})
                    self.close(1013, "too many pages")
                    return
                self.send_json({"class": "WELCOME", "mode": server.mode})
                if server.replay is not None:
                    self.player = Player(server.replay, self, tornado)
                return
            if self.player is not None and isinstance(kind, str):
                error = self.player.command(kind, request)
                if error:
                    self.send_json({"class": "ERROR", "error": error})

        def on_close(self) -> None:
            if self.player is not None:
                self.player.stop()
            server._gone(self)

    return [(r"/", Page), (r"/static/(.*)", Static, {"path": STATIC}), (r"/ws", Socket)]


class Player:
    """One page's playhead over a trace: play, pause, speed, seek; a picture every ``REPLAY_TICK_S``."""

    def __init__(self, replay: Any, page: Any, tornado: Any, clock: Callable[[], float] = time.monotonic):
        from .replay import MAX_SPEED, MIN_SPEED

        self.replay, self.page, self.clock = replay, page, clock
        self.bounds = (MIN_SPEED, MAX_SPEED)
        self.t = replay.start
        self.speed = 1.0
        self.playing = False
        self.last = clock()
        page.send_json(replay.scene_at(self.t))
        self.scene = replay.scene_at(self.t)
        self.timer = tornado.ioloop.PeriodicCallback(self.tick, REPLAY_TICK_S * 1000)
        self.timer.start()
        self.tick(force=True)

    def command(self, kind: str, request: dict) -> str | None:
        self.tick()  # the playhead up to now, at the old speed
        if kind == "PLAY":
            if self.t >= self.replay.end:
                self.t = self.replay.start
            self.playing = True
        elif kind == "PAUSE":
            self.playing = False
        elif kind == "SPEED":
            speed = request.get("speed")
            if isinstance(speed, bool) or not isinstance(speed, (int, float)) or not \
                    self.bounds[0] <= speed <= self.bounds[1]:
                return f"speed must be a number from {self.bounds[0]:g} to {self.bounds[1]:g}"
            self.speed = float(speed)
        elif kind == "SEEK":
            t = request.get("t")
            if isinstance(t, bool) or not isinstance(t, (int, float)) or t != t:
                return "t must be a number of seconds"
            self.t = min(max(float(t), self.replay.start), self.replay.end)
        else:
            return f"unknown command {kind[:40]!r} (PLAY, PAUSE, SPEED, SEEK)"
        self.tick(force=True)
        return None

    def tick(self, force: bool = False) -> None:
        now = self.clock()
        if self.playing:
            self.t += (now - self.last) * self.speed
            if self.t >= self.replay.end:
                self.t = self.replay.end
                self.playing = False
                force = True
        self.last = now
        if not (self.playing or force):
            return
        scene = self.replay.scene_at(self.t)
        if scene is not self.scene:
            self.scene = scene
            self.page.send_json(scene)
        self.page.send_text(json.dumps(self.replay.state(self.t, self.speed, self.playing)), force=force)

    def stop(self) -> None:
        self.timer.stop()
