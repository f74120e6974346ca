"""The socket GLI's conversation, without I/O (h11's way): bytes in, typed events out, and the rules
of who may say what when.

A client on a link's own Unix socket is bound to that link from the start (HELLO is optional there,
and must name the same link); a TCP client must say HELLO first.  SEND and COMMAND need a link; any
other message type, a second HELLO for another link, or broken framing is a :class:`WireError`,
after which the connection cannot continue.  Tested without sockets (``tests/test_gli_session.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterator

from . import wire
from .wire import WireError

__all__ = ["Hello", "Send", "Command", "Session", "WireError"]


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


class Session:
    def __init__(self, link: str | None = None):
        self.decoder = wire.Decoder()
        self.link = link            # the link this connection belongs to, once known
        self.bound = False          # the daemon accepted it (the link exists and had room)
        self.welcomed = False

    def receive(self, data: bytes) -> Iterator[Event]:
        """Events for the bytes a client sent, one at a time (handling a HELLO binds the session before
        the next message is judged); :class:`WireError` where it broke the protocol."""
        for kind, body in self.decoder.feed(data):
            yield self._event(kind, body)

    def _event(self, kind: int, body: bytes) -> Event:
        if kind == wire.HELLO:
            hello = wire.decode_json(body)
            link = hello.get("link") if isinstance(hello, dict) else None
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

    @property
    def pending(self) -> int:
        """Bytes of an unfinished message (a client that left mid-frame)."""
        return self.decoder.pending
