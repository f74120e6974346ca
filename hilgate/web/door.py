"""The web view's door: the connections that have not proved the token yet, their deadline, and what
was refused, on the server's thread.

Every connection is a stranger until its WebSocket proves the token: the page and its scripts are
fetched by strangers too, and a browser opens a new connection for the WebSocket.  Strangers wait in a
:class:`~hilgate.core.waiting_room.WaitingRoom` (at most :data:`PER_ADDRESS` from one address,
:data:`WAITING` in all; a newcomer is always let in and the oldest of the address holding the most
makes room, so 64 idle connections no longer keep the operator out, issue 37 item 5), and each is
closed ``auth_timeout_s`` after it connected: one deadline for the whole handshake (request, upgrade,
proof), however slowly its bytes come.  A page that proved the token leaves the room; pages are
bounded apart (``max_pages``).

Refusals are counted by cause (:attr:`WebDoor.refused`, in ``hilgate status``) and logged the 1st,
2nd, 4th, 8th… time of each cause, so a flood costs a few lines.  A request is logged without its
query (:func:`request_line`): a token given as ``?token=`` would otherwise be in the daemon's log.
"""

from __future__ import annotations

import logging
from typing import Any

from ..core.waiting_room import WaitingRoom

__all__ = ["WebDoor", "request_line", "WAITING", "PER_ADDRESS"]

log = logging.getLogger(__name__)

WAITING = 64
PER_ADDRESS = 8
CAUSES = ("auth", "auth_timeout", "auth_pending", "host", "origin", "pages")


def request_line(request: Any) -> str:
    """``METHOD /path?… (address)`` of a tornado request: the query is never shown (a token may be in it)."""
    path = request.path if len(request.path) <= 200 else request.path[:200] + "…"
    query = "?…" if "?" in request.uri else ""
    line = f"{request.method} {path}{query} ({request.remote_ip})"
    return line.encode("ascii", "backslashreplace").decode()


class WebDoor:
    """The strangers of one web server (its thread only, but for :meth:`status`)."""

    def __init__(self, ioloop: Any, auth_timeout_s: float, total: int = WAITING, per_address: int = PER_ADDRESS):
        self.ioloop = ioloop
        self.auth_timeout_s = auth_timeout_s
        self.room = WaitingRoom(total, per_address)
        self.refused = dict.fromkeys(CAUSES, 0)
        self._waiting: dict[Any, tuple[str, Any]] = {}  # stream -> (address, deadline's timer)
        self._pages: dict[Any, Any] = {}                # stream -> its WebSocket handler, once it has one

    def status(self) -> dict[str, Any]:
        """What was refused, by cause, and how many wait (read from the daemon's thread: plain numbers)."""
        return {"refused": dict(self.refused), "waiting": len(self.room)}

    def arrive(self, stream: Any, address: str) -> None:
        """A new connection: in the room, making room if it must, with its deadline."""
        for gone in [s for s in self._waiting if s.closed()]:  # left without a word: no place held
            self.leave(gone)
        for older in self.room.admit(stream, address):
            older_address = self._waiting[older][0]
            self.refuse("auth_pending", older_address,
                        f"too many connections wait to prove the token from {older_address}: the oldest is closed")
            self._close(older, "too many connections wait to prove the token")
        timer = self.ioloop.call_later(self.auth_timeout_s, self._deadline, stream)
        self._waiting[stream] = (address, timer)

    def opened(self, stream: Any, page: Any) -> None:
        """``stream`` is now ``page``'s WebSocket: closed with a WebSocket close code if it must go."""
        if stream in self._waiting:
            self._pages[stream] = page

    def proved(self, stream: Any) -> None:
        """The page proved the token: no deadline, no place in the room any more."""
        self.leave(stream)

    def leave(self, stream: Any) -> None:
        self.room.leave(stream)
        self._pages.pop(stream, None)
        entry = self._waiting.pop(stream, None)
        if entry is not None:
            self.ioloop.remove_timeout(entry[1])

    def refuse(self, cause: str, address: str, detail: str) -> None:
        self.refused[cause] += 1
        count = self.refused[cause]
        if count & (count - 1) == 0:
            log.warning("web view: refused %s: %s (%d refused so far for this cause)", address, detail, count)

    def _deadline(self, stream: Any) -> None:
        entry = self._waiting.get(stream)
        if entry is None:
            return
        if not stream.closed():
            self.refuse("auth_timeout", entry[0], f"no proof of the token within {self.auth_timeout_s:g} s")
            self._close(stream, "no proof of the token")
        self.leave(stream)

    def _close(self, stream: Any, reason: str) -> None:
        page = self._pages.get(stream)
        self.leave(stream)
        if page is not None:
            page.close(1008, reason)
        else:
            stream.close()
