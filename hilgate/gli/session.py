"""The socket GLI's conversation, without I/O (h11's way): bytes in, typed events out, and the rules
of who may say what when.

A client on a link's own Unix socket is bound to that link from the start (HELLO is optional there,
and must name the same link); a TCP client must say HELLO first, with the proof that it holds the
daemon's token (:mod:`hilgate.gli.token`): a session made with a ``check`` has sent a CHALLENGE, and
a HELLO without the right answer to it is refused before the link it names is even looked up.  SEND
and COMMAND need a link; any other message type, a second HELLO for another link, or broken framing
is a :class:`WireError`, after which the connection cannot continue.  Tested without sockets
(``tests/test_gli_session.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterator

from . import wire
from .token import TokenCheck
from .wire import WireError

__all__ = ["Hello", "Send", "Command", "Session", "AuthError", "WireError"]


@dataclass(frozen=True)
class Hello:
    """Bind to ``link`` (``first``: the link has not been welcomed yet on this connection)."""

    link: str
    first: bool


@dataclass(frozen=True)
class Send:
    dst: int
    payload: bytes


@dataclass(frozen=True)
class Command:
    request: Any


Event = Hello | Send | Command


class AuthError(WireError):
    """A HELLO on TCP without the right proof of the token."""


class Session:
    def __init__(self, link: str | None = None, check: TokenCheck | None = None):
        self.decoder = wire.Decoder()
        self.link = link            # the link this connection belongs to, once known
        self.bound = False          # the daemon accepted it (the link exists and had room)
        self.welcomed = False
        self.check = check
        self.nonce = check.challenge() if check is not None else None
        self.authenticated = check is None

    def challenge(self) -> bytes:
        """The CHALLENGE to send first (a session with a token check only)."""
        return wire.encode_json(wire.CHALLENGE, {"nonce": self.nonce.hex()})

    def receive(self, data: bytes) -> Iterator[Event]:
        """Events for the bytes a client sent, one at a time (handling a HELLO binds the session before
        the next message is judged); :class:`WireError` where it broke the protocol."""
        for kind, body in self.decoder.feed(data):
            yield self._event(kind, body)

    def _event(self, kind: int, body: bytes) -> Event:
        if kind == wire.HELLO:
            hello = wire.decode_json(body)
            link = hello.get("link") if isinstance(hello, dict) else None
            if not self.authenticated:
                self._authenticate(hello)
            if not isinstance(link, str):
                raise WireError('HELLO needs {"link": "<id>"}')
            if self.link is not None and link != self.link:
                raise WireError(f"this socket belongs to link {self.link[:100]!r}")
            self.link = link
            first = not self.welcomed
            self.welcomed = True
            return Hello(link, first)
        if kind in (wire.SEND, wire.COMMAND) and not self.bound:
            raise WireError("say HELLO first")
        if kind == wire.SEND:
            dst, payload = wire.decode_send(body)
            return Send(dst, payload)
        if kind == wire.COMMAND:
            return Command(wire.decode_json(body))
        raise WireError(f"unexpected message type {kind}")

    def _authenticate(self, hello: Any) -> None:
        answer = hello.get("proof") if isinstance(hello, dict) else None
        if answer is None:
            raise AuthError('this TCP listener needs proof of the daemon\'s token: HELLO {"link", "proof"} '
                            "answering its CHALLENGE (hilgate.client: Link.open(..., tcp=..., token_file=...))")
        if not self.check.verify(self.nonce, answer):
            raise AuthError("authentication failed: the proof does not match this daemon's token")
        self.authenticated = True

    @property
    def pending(self) -> int:
        """Bytes of an unfinished message (a client that left mid-frame)."""
        return self.decoder.pending
