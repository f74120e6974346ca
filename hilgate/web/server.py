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
send to a server) or typed in, and keeps it for the tab only (sessionStorage).  A request for a name
that is not the view's is refused (:mod:`.hosts`: DNS rebinding), WebSockets from pages of other
origins too (a web site the operator visits cannot even start the challenge); what is said before the
proof names no file.  Connections that have not proved the token are bounded per address and in all,
make room for a newcomer, and are closed ``auth_timeout_s`` after they connected (:mod:`.door`); at
most ``max_pages`` pages are served at once.  Static files are the folder's own, by name; the log
shows no request's query (a token given as ``?token=`` stays out of it).
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

from .door import WebDoor, request_line
from .hosts import HostNames

__all__ = ["MissingTornado", "WebServer", "parse_web", "MAX_PAGES"]

log = logging.getLogger(__name__)

STATIC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "static")
MAX_PAGES = 8
AUTH_TIMEOUT_S = 5.0
"""From the connection on, to prove the token (a request, an upgrade, one round trip)."""
TOKEN_HINT = "the daemon's token (`hilgate view` on its host prints the address with it)"
"""What a page that has not proved the token is told to give: where to get it, but no path."""
MAX_MESSAGE = 4096
"""A page's messages are a proof or a player command: tens of bytes."""
PING_S = 10
"""A page is pinged this often and closed when its pong is this late: it went without closing (a laptop shut)."""
REPLAY_TICK_S = 0.05
"""The trace player's pictures: 20 a second."""
MISSING = ("the web view needs tornado, an optional extra: pip install 'hilgate[web]' (or pip install tornado)")


class MissingTornado(OSError):
    """tornado is not installed; the message says how to install it (an OSError: the command's one-line
    error, as for a port in use).  Exit status 2, a configuration error: under the systemd unit
    (``RestartPreventExitStatus=2``) a restart every 2 s cannot install it."""

    exit_status = 2


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
                 token_hint: str = TOKEN_HINT, token_file: str = "", auth_timeout_s: float = AUTH_TIMEOUT_S):
        tornado = _tornado()
        self.check = check
        self.replay = replay
        self.mode = "live" if replay is None else "replay"
        self.max_pages = max_pages
        self.token_hint = token_hint  # said to pages without the token: no path
        self.token_file = token_file  # said only over the control socket (hilgate status: the daemon's group)
        self.auth_timeout_s = auth_timeout_s
        self.hosts = HostNames(host)
        self.door: WebDoor | None = None      # made on the server's thread, with its loop
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

    def status(self) -> dict[str, Any]:
        """What the door refused, by cause, and how many connections wait to prove the token."""
        if self.door is None:
            return {"refused": {}, "waiting": 0}
        return self.door.status()

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
        self.door = WebDoor(self._ioloop, self.auth_timeout_s)
        # one number for both: tornado (6.5 on) caps the timeout at the interval and warns when it is longer
        app = tornado.web.Application(_handlers(self, tornado), websocket_max_message_size=MAX_MESSAGE,
                                      websocket_ping_interval=PING_S, websocket_ping_timeout=PING_S,
                                      compress_response=False, log_function=_log_request)
        server = _door_server(tornado, self.door)(app, idle_connection_timeout=60, body_timeout=10,
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
        # WELCOME first: a page (or a client) reads what follows as the welcomed page's, whatever the scene's timing
        page.send_json({"class": "WELCOME", "mode": self.mode})
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


def _door_server(tornado: Any, door: WebDoor) -> Any:
    class DoorServer(tornado.httpserver.HTTPServer):
        """Every connection comes through the door: a stranger until its page proves the token."""

        def handle_stream(self, stream: Any, address: Any) -> None:
            door.arrive(stream, str(address[0]) if isinstance(address, tuple) and address else "")
            super().handle_stream(stream, address)

    return DoorServer


def _log_request(handler: Any) -> None:
    """tornado's access log line, without the request's query (:func:`.door.request_line`)."""
    status = handler.get_status()
    level = logging.INFO if status < 400 else logging.WARNING if status < 500 else logging.ERROR
    log.log(level, "%d %s %.2fms", status, request_line(handler.request), 1000.0 * handler.request.request_time())


def _handlers(server: WebServer, tornado: Any) -> list:
    web = tornado.web
    static_files = frozenset(name for name in os.listdir(STATIC)
                             if not name.startswith(".") and os.path.isfile(os.path.join(STATIC, name)))

    class Guarded:
        """What every handler of the view does first: answer only to the view's own names, and log a
        failure without the request's query."""

        def prepare(self) -> None:
            host = self.request.headers.get("Host")
            if not server.hosts.allows(host):
                server.door.refuse("host", self.request.remote_ip,
                                   f"a request for {host[:100]!r}, not a name of this view (DNS rebinding?)")
                raise web.HTTPError(403, reason="Not a name of this view")

        def write_error(self, status_code: int, **kwargs: Any) -> None:
            self.set_header("Content-Type", "text/plain; charset=utf-8")
            if status_code == 403 and not server.hosts.allows(self.request.headers.get("Host")):
                self.finish(f"this view answers to {server.hosts.describe()}\n")
            else:
                self.finish(f"{status_code} {self._reason}\n")

        def log_exception(self, typ: Any, value: Any, tb: Any) -> None:
            if isinstance(value, web.HTTPError):
                return  # answered with its status, which the access log says
            log.error("web view: %s failed", request_line(self.request), exc_info=(typ, value, tb))

    def harden(handler: Any) -> None:
        handler.set_header("X-Content-Type-Options", "nosniff")
        handler.set_header("X-Frame-Options", "DENY")
        handler.set_header("Referrer-Policy", "no-referrer")
        handler.set_header("Content-Security-Policy",
                           "default-src 'self'; connect-src 'self'; img-src 'self' data:; "
                           "style-src 'self'; script-src 'self'; frame-ancestors 'none'")

    class Page(Guarded, web.RequestHandler):
        def set_default_headers(self) -> None:
            harden(self)
            self.set_header("Cache-Control", "no-store")

        def get(self) -> None:
            with open(os.path.join(STATIC, "index.html"), "rb") as handle:
                self.set_header("Content-Type", "text/html; charset=utf-8")
                self.write(handle.read())

    class Static(Guarded, web.StaticFileHandler):
        """The folder's own files, by name: nothing else is even looked up (a path with a NUL byte was
        an HTTP 500 with a traceback)."""

        def set_default_headers(self) -> None:
            harden(self)

        def parse_url_path(self, url_path: str) -> str:
            if url_path not in static_files:
                raise web.HTTPError(404)
            return url_path

    class Socket(Guarded, tornado.websocket.WebSocketHandler):
        """One page: HELLO with a nonce, its AUTH, then pictures (and, for a trace, its player's commands)."""

        door_stream: Any = None  # its connection, the door's key (once open)

        def check_origin(self, origin: str) -> bool:
            if super().check_origin(origin):
                return True
            server.door.refuse("origin", self.request.remote_ip, f"a WebSocket from a page of {origin[:100]!r}")
            return False

        def open(self) -> None:
            self.peer = self.request.remote_ip
            self.nonce = server.check.challenge()
            self.authed = False
            self.pending: Any = None   # the last picture's write, while it has not gone out
            self.behind = False
            self.player: Any = None
            self.door_stream = self.ws_connection.stream
            server.connections.add(self)
            server.door.opened(self.door_stream, self)
            self.send_json({"class": "HELLO", "mode": server.mode, "nonce": self.nonce.hex()})

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
                    server.door.refuse("auth", self.peer, "a page did not prove the token")
                    self.send_json({"class": "ERROR", "error": f"the token's proof is wrong: give {server.token_hint}"})
                    self.close(1008, "wrong proof")
                    return
                self.authed = True
                server.door.proved(self.door_stream)
                if not server._welcome(self):
                    server.door.refuse("pages", self.peer, f"{server.max_pages} pages are served already")
                    self.send_json({"class": "ERROR", "error": f"too many pages at once ({server.max_pages})"})
                    self.close(1013, "too many pages")
                    return
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
            if self.door_stream is not None:
                server.door.leave(self.door_stream)
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
        page.send_json({"class": "EVENTS", "events": replay.events, "start": replay.start, "end": replay.end})
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
        floor = 2 * REPLAY_TICK_S * self.speed  # every transmission since the last picture
        self.page.send_text(json.dumps(self.replay.state(self.t, self.speed, self.playing, floor)), force=force)

    def stop(self) -> None:
        self.timer.stop()
