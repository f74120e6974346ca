"""A small client for hilgate's socket GLI: open a link by id, send with a destination, receive.

    from hilgate.client import Link

    with Link.open("rov0_rf") as link:          # the link's Unix socket on this machine
        link.send(b"hello", dst=2)               # dst 255 (the default) broadcasts
        message = link.recv(timeout=5.0)         # None on timeout
        print(message.src, message.data)

    Link.open("rov0_rf", tcp=("topside", 4280), token_file="tcp.token")  # the daemon's --tcp listener
    Link.open("rov0_rf", zenoh="tcp/topside:7447")  # from any host of a network of daemons (Zenoh)
    Link.open("rov0_rf", zenoh="tcp/topside:7447", prefix="lab2")  # a network whose scene sets zenoh: prefix

Blocking and single-threaded on purpose: one object per link per thread.  The framing is
documented in :mod:`hilgate.gli.wire` for applications in other languages.
"""

from __future__ import annotations

import os
import socket
import time
from collections import deque
from typing import Any

from . import wire
from .token import TOKEN_FILE, TokenError, proof, read_token
from ..core.application import Message
from ..core.packets import BROADCAST
from ..core.names import zenoh_prefix_problem
from ..core.paths import client_runtime_dir

TOKEN_FILE_VARIABLE = "HILGATE_TCP_TOKEN_FILE"

__all__ = ["Link", "Message", "GliError"]


class GliError(RuntimeError):
    """hilgate refused something (unknown link, payload too large, …)."""


def zenoh_options(zenoh: Any) -> dict[str, Any]:
    """``zenoh=`` as a dict: an endpoint, a list of them, or the dict itself."""
    if isinstance(zenoh, str):
        return {"connect": [zenoh]}
    if isinstance(zenoh, (list, tuple)):
        return {"connect": list(zenoh)}
    return dict(zenoh)


def unreachable(link_id: str, runtime: str, path: str, exc: OSError) -> str:
    """Why ``link_id``'s socket could not be reached, and what to do: a daemon runs there without that
    link (its links named), or no daemon runs in that runtime directory (``--runtime-dir`` named)."""
    if not _daemon_listens(os.path.join(runtime, "control.sock")):
        return (f"no hilgate daemon runs with the runtime directory {runtime} (cannot reach link {link_id!r}): "
                f"start one, or give this command the --runtime-dir the daemon was started with")
    try:
        links = sorted(name[:-5] for name in os.listdir(os.path.join(runtime, "gli")) if name.endswith(".sock"))
    except OSError:
        links = []
    if not os.path.exists(path):
        served = f"its links: {', '.join(links)}" if links else "it serves no link over its sockets"
        return f"the daemon at {runtime} serves no link {link_id!r} over its sockets; {served}"
    return f"cannot reach link {link_id!r} at {path}: {exc.strerror or exc}"


def _daemon_listens(control: str) -> bool:
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    probe.settimeout(1.0)
    try:
        probe.connect(control)
        return True
    except OSError:
        return False
    finally:
        probe.close()


class Link:
    def __init__(self, sock: socket.socket, link_id: str):
        self.sock = sock
        self.id = link_id
        self.decoder = wire.Decoder()
        self.inbox: deque[Message] = deque()
        self.replies: deque[Any] = deque()
        self.errors: deque[str] = deque()
        self.ready = False
        self.info: dict[str, Any] = {}
        self.nonce: bytes | None = None  # the TCP listener's CHALLENGE

    @classmethod
    def open(cls, link_id: str, *, tcp: tuple[str, int] | None = None, runtime_dir: str | None = None,
             timeout: float = 5.0, zenoh: Any = None, prefix: str | None = None, token: str | bytes | None = None,
             token_file: str | None = None) -> "Link":
        """``tcp``: the daemon's ``--tcp`` listener, where the application proves that it holds the
        daemon's token (:mod:`hilgate.gli.token`): ``token``, else the file ``token_file``, else
        ``$HILGATE_TCP_TOKEN_FILE``, else the local daemon's ``RUNTIME/tcp.token`` (readable by its group).

        ``zenoh``: reach the link over Zenoh from any host of a network of daemons (an endpoint
        such as ``"tcp/10.0.0.5:7447"``, a list, or ``{"connect": [...], "prefix": ...}``); the object
        returned has the same methods (:class:`hilgate.gli.zenoh_client.ZenohLink`).  ``prefix``: the
        network's Zenoh key prefix, as its scene's ``zenoh: prefix:`` (default ``hilgate``)."""
        if prefix is not None and zenoh is None:
            raise ValueError("prefix= is the key prefix of a Zenoh network: give zenoh= too")
        if prefix is not None and zenoh_prefix_problem(prefix):
            raise ValueError(f"prefix={prefix!r}: {zenoh_prefix_problem(prefix)}")
        if zenoh is not None:
            from .zenoh_client import ZenohLink

            if prefix is not None:
                zenoh = {**zenoh_options(zenoh), "prefix": prefix}
            return ZenohLink.open(link_id, zenoh, timeout)  # type: ignore[return-value]
        secret = None
        if tcp is not None:
            secret = _token(token, token_file, runtime_dir)  # before connecting: no token, no traffic
        sock = _connect(link_id, tcp, runtime_dir, timeout)
        link = cls(sock, link_id)
        try:
            deadline = time.monotonic() + timeout
            hello: dict[str, Any] = {"link": link_id}
            if secret is not None:
                while link.nonce is None:  # the CHALLENGE comes first
                    link._pump(max(0.0, deadline - time.monotonic()))
                    if link.errors:
                        raise GliError(link.errors.popleft())
                    if time.monotonic() >= deadline and link.nonce is None:
                        raise GliError(f"no CHALLENGE from hilgate at {tcp[0]}:{tcp[1]} (not a hilgate TCP GLI?)")
                hello["proof"] = proof(secret, link.nonce)
            link._connected()
            try:
                sock.sendall(wire.encode_json(wire.HELLO, hello))
            except (BrokenPipeError, ConnectionResetError):
                pass  # hilgate refused the connection at once (a full link): its ERROR waits to be read
            while not link.info:
                link._pump(max(0.0, deadline - time.monotonic()))
                if link.errors:
                    raise GliError(link.errors.popleft())
                if time.monotonic() >= deadline and not link.info:
                    raise GliError(f"no answer from hilgate for link {link_id!r}")
        except BaseException:
            sock.close()
            raise
        return link

    def _connected(self) -> None:
        """Called between connecting and HELLO (a test makes the client slow there)."""

    @property
    def address(self) -> int:
        return int(self.info["address"])

    @property
    def max_payload(self) -> int:
        return int(self.info["max_payload"])

    def send(self, data: bytes, dst: int = BROADCAST, timeout: float | None = None) -> None:
        """Send one frame; blocks while hilgate is not reading (or up to ``timeout`` seconds, then
        TimeoutError).  Independent of any timeout an earlier :meth:`recv` used."""
        if not 0 <= dst <= 255:
            raise ValueError("dst must be 0..255 (255 broadcasts)")
        self._sendall(wire.encode_send(dst, bytes(data)), timeout)

    def _sendall(self, data: bytes, timeout: float | None) -> None:
        self.sock.settimeout(timeout)
        self.sock.sendall(data)

    def recv(self, timeout: float | None = None) -> Message | None:
        """The next frame for this link, or None if none came within ``timeout`` seconds."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self.inbox:
            if self.errors:
                raise GliError(self.errors.popleft())
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return None
            if not self._pump(remaining):
                if deadline is None:
                    continue
        return self.inbox.popleft()

    def command(self, request: dict[str, Any], timeout: float = 5.0) -> Any:
        """Ask hilgate something about this link or its vehicle (a JSON object with a ``class``).

        hilgate answers in order, so an ERROR that came before the reply (a frame sent earlier was
        refused) is raised here, after the reply is taken off the queue."""
        self._sendall(wire.encode_json(wire.COMMAND, request), timeout)
        deadline = time.monotonic() + timeout
        while not self.replies:  # (a connection hilgate closes ends this with a GliError)
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise GliError(self.errors.popleft() if self.errors else "no reply from hilgate")
            self._pump(remaining)
        reply = self.replies.popleft()
        if self.errors:
            raise GliError(self.errors.popleft())
        return reply

    def _pump(self, timeout: float | None) -> bool:
        self.sock.settimeout(timeout)
        try:
            data = self.sock.recv(65536)
        except socket.timeout:
            return False
        except ConnectionResetError:
            raise GliError("hilgate closed the connection (reset)") from None
        if not data:
            raise GliError("hilgate closed the connection")
        for kind, body in self.decoder.feed(data):
            if kind == wire.RECV:
                src, dst, t, payload = wire.decode_recv(body)
                self.inbox.append(Message(self.id, src, dst, t, payload))
            elif kind == wire.STATE:
                self.ready = body[:1] == b"\x01"
            elif kind == wire.WELCOME:
                self.info = wire.decode_json(body)
            elif kind == wire.REPLY:
                self.replies.append(wire.decode_json(body))
            elif kind == wire.ERROR:
                self.errors.append(str(wire.decode_json(body).get("error")))
            elif kind == wire.CHALLENGE:
                challenge = wire.decode_json(body)
                nonce = challenge.get("nonce") if isinstance(challenge, dict) else None
                try:
                    self.nonce = bytes.fromhex(nonce)
                except (TypeError, ValueError):
                    raise GliError("a CHALLENGE without a nonce") from None
        return True

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> "Link":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _connect(link_id: str, tcp: tuple[str, int] | None, runtime_dir: str | None, timeout: float) -> socket.socket:
    """A socket connected to the daemon: its TCP GLI at ``tcp``, else the link's Unix socket under its runtime
    folder; a GliError that says why not."""
    if tcp is not None:
        try:
            sock = socket.create_connection(tcp, timeout=timeout)
        except OSError as exc:
            raise GliError(f"cannot reach hilgate's TCP GLI at {tcp[0]}:{tcp[1]}: {exc.strerror or exc}") from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return sock
    runtime = client_runtime_dir(runtime_dir)
    path = os.path.join(runtime, "gli", f"{link_id}.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(timeout)
    try:
        sock.connect(path)
    except OSError as exc:
        sock.close()
        raise GliError(unreachable(link_id, runtime, path, exc)) from None
    return sock


def _token(token: str | bytes | None, token_file: str | None, runtime_dir: str | None) -> bytes:
    """The TCP GLI token the application was given, or the one it can read (see :meth:`Link.open`)."""
    if token is not None:
        return token.encode() if isinstance(token, str) else bytes(token)
    path = token_file or os.environ.get(TOKEN_FILE_VARIABLE)
    if not path:
        path = os.path.join(client_runtime_dir(runtime_dir), TOKEN_FILE)
        if not os.path.exists(path):
            raise GliError(f"the TCP GLI needs the daemon's token and there is none at {path}: give token_file= "
                           f"(hilgate --token-file, ${TOKEN_FILE_VARIABLE}) the daemon's RUNTIME/{TOKEN_FILE} or "
                           f"its --tcp-token file")
    try:
        return read_token(path)
    except TokenError as exc:
        raise GliError(str(exc)) from None
