"""``hilgate app MODULE:CLASS --link ID …``: an application (:class:`hilgate.app.Application`) as its own
process against a running daemon, on the wall clock, through the GLI (the link's Unix socket, the
daemon's TCP listener, or Zenoh).  The same class runs in ``hilgate sim`` in virtual time.

``ctx.now()`` is seconds since the application started; a message's ``t`` is the daemon's model time
of the delivery.  ``ctx.vehicle(name)`` reaches a vehicle through one of the application's links that
is on it (the daemon answers POSE, GOTO, VELOCITY and STOP about a link's own vehicle).  One loop
(:class:`hilgate.core.realtime.RealtimeScheduler`) runs the timers and the links' sockets, so an
application never needs a thread.
"""

from __future__ import annotations

import logging
import random
import signal
from collections import deque
from typing import Any, Callable

from ..core.application import Application, ContextBase, Message
from ..core.paths import client_runtime_dir
from ..core.realtime import RealtimeScheduler
from .client import GliError, Link

log = logging.getLogger(__name__)

__all__ = ["RealtimeContext", "run_application"]

POLL_S = 0.002  # how often a Zenoh link's inbox is looked at (Zenoh delivers on its own threads)


class _Vehicle:
    def __init__(self, link: Any, name: str):
        self.link = link
        self.name = name

    def _ask(self, request: dict) -> dict:
        answer = self.link.command(request)
        if answer.get("class") == "ERROR":
            raise GliError(str(answer.get("error")))
        return answer

    def pose(self) -> tuple[float, float, float] | None:
        position = self._ask({"class": "POSE"}).get("position")
        return None if position is None else tuple(position)

    def goto(self, position: Any) -> None:
        self._ask({"class": "GOTO", "position": [float(v) for v in position]})

    def velocity(self, velocity: Any) -> None:
        self._ask({"class": "VELOCITY", "velocity": [float(v) for v in velocity]})

    def stop(self) -> None:
        self._ask({"class": "STOP"})


class _CountedLink:
    """What ``ctx.link(id)`` returns in real time: the link, counting what the application sent on it
    for the summary ``hilgate app`` prints at exit."""

    def __init__(self, link: Any):
        self._link = link
        self.sent = 0
        self.received = 0
        self.refused = 0

    def send(self, payload: bytes, dst: int = 255) -> None:
        self._link.send(payload, dst)
        self.sent += 1

    def __getattr__(self, name: str) -> Any:
        return getattr(self._link, name)


def _attached(link_id: str, link: Any, runtime_dir: str | None, tcp: tuple[str, int] | None) -> str:
    """One line about a link just opened: its address, its backend (asked of the daemon), and the way in."""
    try:
        backend = link.command({"class": "STATUS"}).get("link", {}).get("backend", "?")
    except (GliError, OSError):
        backend = "?"
    if getattr(link, "sock", None) is None:
        via = f"Zenoh, prefix {link.prefix}" + (f", host {link.info['host']}" if link.info.get("host") else "")
    elif tcp is not None:
        via = f"TCP {tcp[0]}:{tcp[1]}"
    else:
        via = f"socket {client_runtime_dir(runtime_dir)}/gli/{link_id}.sock"
    return f"link {link_id}: address {link.address}, backend {backend}, {link.info.get('packet', '?')}; through {via}"


class RealtimeContext(ContextBase):
    def __init__(self, scheduler: RealtimeScheduler, name: str, links: dict[str, Any], params: dict[str, Any],
                 seed: int | None):
        self.clock = scheduler
        self.name = name
        self.links = tuple(links)
        self.params = params
        self.random = random.Random(f"{seed}/app/{name}" if seed is not None else None)
        self.log = logging.getLogger(f"hilgate.app.{name}")
        self._links = links
        self._vehicles: dict[str, _Vehicle] = {}

    def vehicle(self, name: str) -> _Vehicle:
        if name not in self._vehicles:
            for link in self._links.values():
                if link.command({"class": "POSE"}).get("vehicle") == name:
                    self._vehicles[name] = _Vehicle(link, name)
                    break
            else:
                raise KeyError(f"none of the links {', '.join(self.links)} is on vehicle {name!r}")
        return self._vehicles[name]


def run_application(cls: type[Application], link_ids: list[str], params: dict[str, Any], *, name: str | None = None,
                    seed: int | None = None, runtime_dir: str | None = None, tcp: tuple[str, int] | None = None,
                    zenoh: Any = None, until: float | None = None, token_file: str | None = None,
                    report: Callable[[str], None] | None = None) -> int:
    """Open the links, run the application until SIGTERM/SIGINT (or ``until`` seconds), then stop it.
    ``report`` is told, in one line each, every link once it is open and what was sent and received
    on each at the end (``hilgate app`` prints them: an application that prints nothing itself still
    shows that it ran)."""
    links: dict[str, Any] = {}
    name = name or cls.__name__
    try:
        for link_id in link_ids:
            links[link_id] = Link.open(link_id, runtime_dir=runtime_dir, tcp=tcp, zenoh=zenoh, token_file=token_file)
            if report is not None:
                report(f"{name}: {_attached(link_id, links[link_id], runtime_dir, tcp)}")
        scheduler = RealtimeScheduler()
        app = cls()
        counted = {link_id: _CountedLink(link) for link_id, link in links.items()}
        context = RealtimeContext(scheduler, name, counted, params, seed)

        def drain(link_id: str) -> None:
            link = links[link_id]
            inbox = link.inbox
            while True:
                if isinstance(inbox, deque):  # a socket link: filled by _pump on this thread
                    while link.errors:  # a frame the daemon refused: said, not raised into the loop
                        counted[link_id].refused += 1
                        context.log.warning("link %s: %s", link_id, link.errors.popleft())
                    message = inbox.popleft() if inbox else None
                else:  # a Zenoh link: filled by Zenoh's threads
                    try:
                        message = link.recv(timeout=0)
                    except GliError as exc:
                        counted[link_id].refused += 1
                        context.log.warning("link %s: %s", link_id, exc)
                        continue
                if message is None:
                    return
                counted[link_id].received += 1
                app.on_receive(context, Message(link_id, message.src, message.dst, message.t, message.data))

        for link_id, link in links.items():
            sock = getattr(link, "sock", None)
            if sock is not None:
                def readable(link_id: str = link_id, link: Any = link) -> None:
                    try:
                        link._pump(0)
                    except BlockingIOError:
                        return
                    except GliError as exc:  # the daemon closed the link: the application ends
                        log.error("link %s: %s", link_id, exc)
                        scheduler.stop()
                        return
                    drain(link_id)

                scheduler.add_reader(sock.fileno(), readable)
            else:  # Zenoh: its threads fill the inbox
                def poll(link_id: str = link_id) -> None:
                    drain(link_id)
                    scheduler.after_wall(POLL_S, poll)

                scheduler.after_wall(POLL_S, poll)

        def after_commands() -> None:  # a reply read during a COMMAND may have brought frames with it
            for link_id, link in links.items():
                if isinstance(link.inbox, deque) and link.inbox:
                    drain(link_id)
            scheduler.after_wall(0.05, after_commands)

        scheduler.after_wall(0.05, after_commands)
        scheduler.on_signal(signal.SIGTERM, lambda s: scheduler.stop())
        scheduler.on_signal(signal.SIGINT, lambda s: scheduler.stop())
        scheduler.at(0.0, app.on_start, context)
        scheduler.run(until if until is not None else float("inf"))
        app.on_stop(context)
        if report is not None:
            report(f"{name}: stopped after {context.now():.1f} s; " + "; ".join(
                f"link {link_id}: {c.sent} frames sent, {c.received} received"
                + (f", {c.refused} refused by the daemon" if c.refused else "") for link_id, c in counted.items()))
        scheduler.close()
        return 0
    finally:
        for link in links.values():
            link.close()
