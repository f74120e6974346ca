"""Applications written once, run in two worlds: in-process on the model's clock (``hilgate sim``,
deterministic) or as their own process against a running daemon (``hilgate app``, the wall clock).

An application is a class with hooks; everything it does goes through the context it is handed::

    from hilgate.app import Application

    class Ping(Application):
        def on_start(self, ctx):
            self.sent = 0
            ctx.every(ctx.params.get("period_s", 10.0), self.ping)

        def ping(self, ctx):
            self.sent += 1
            ctx.link(ctx.links[0]).send(b"ping %d" % self.sent, dst=2)

        def on_receive(self, ctx, message):
            ctx.log.info("%s from %d at %.3f", message.data, message.src, ctx.now())

The context (:class:`Context`) offers ``now()``, ``after(seconds, fn, *args)``, ``every(period, fn,
*args)``, ``cancel(handle)``, ``link(id).send(payload, dst)`` and ``.address``, ``vehicle(name).pose()``
and, for ``controlled`` vehicles, ``.goto(position)``, ``.velocity(v)``, ``.stop()``; ``random`` (a
``random.Random`` seeded from the scene's seed and the application's name), ``params``, ``links``,
``name`` and ``log``.  Timer callbacks get the context as first argument.  Nothing else: no sockets,
threads or sleeping — that is what lets the same class run in virtual time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol

__all__ = ["Application", "Context", "Message", "LinkHandle", "VehicleHandle"]


@dataclass(frozen=True)
class Message:
    """A frame an application's link received: from address ``src`` to ``dst`` at model time ``t``, on
    the link with id ``link``.  One class wherever an application receives: ``hilgate.app`` (an
    application run by ``hilgate sim`` or ``hilgate app``) and ``hilgate.client`` (``Link.recv``)."""

    link: str
    src: int
    dst: int
    t: float
    data: bytes


class LinkHandle(Protocol):
    address: int

    def send(self, payload: bytes, dst: int = 255) -> None: ...


class VehicleHandle(Protocol):
    def pose(self) -> tuple[float, float, float] | None: ...

    def goto(self, position: tuple[float, float, float]) -> None: ...

    def velocity(self, velocity: tuple[float, float, float]) -> None: ...

    def stop(self) -> None: ...


class Context(Protocol):
    name: str
    links: tuple[str, ...]
    params: dict[str, Any]
    random: Any
    log: Any

    def now(self) -> float: ...

    def after(self, seconds: float, fn: Callable[..., Any], *args: Any) -> Any: ...

    def every(self, period: float, fn: Callable[..., Any], *args: Any) -> Any: ...

    def cancel(self, handle: Any) -> None: ...

    def link(self, link_id: str) -> LinkHandle: ...

    def vehicle(self, name: str) -> VehicleHandle: ...


class Application:
    """Subclass it and override what you need; the hooks do nothing by default."""

    def on_start(self, ctx: Context) -> None:
        """The application starts (model time 0 in ``hilgate sim``; when its links are open in real time)."""

    def on_receive(self, ctx: Context, message: Message) -> None:
        """A frame for one of its links."""

    def on_stop(self, ctx: Context) -> None:
        """The run ends (``hilgate sim`` at its end; SIGTERM/SIGINT in real time)."""


class Repeating:
    """What :meth:`Context.every` returns: cancel it to stop the repetition."""

    __slots__ = ("cancelled", "handle")

    def __init__(self) -> None:
        self.cancelled = False
        self.handle: Any = None


class ContextBase:
    """What the contexts of both worlds share: timers on ``clock`` (the virtual scheduler or the
    real-time one, which have the same ``now``/``at``/``cancel``) and finding a link by id in
    ``_links``.  Callbacks get the context as their first argument."""

    clock: Any
    name: str
    links: tuple[str, ...]
    _links: dict[str, Any]

    def now(self) -> float:
        return self.clock.now()

    def after(self, seconds: float, fn: Callable[..., Any], *args: Any) -> Any:
        return self.clock.at(self.clock.now() + max(0.0, float(seconds)), fn, self, *args)

    def every(self, period: float, fn: Callable[..., Any], *args: Any) -> Repeating:
        if not period > 0:
            raise ValueError("every() needs a positive period")
        repeating = Repeating()
        start = self.clock.now()

        def tick(k: int) -> None:
            if repeating.cancelled:
                return
            repeating.handle = self.clock.at(start + (k + 1) * period, tick, k + 1)  # start + k·period: no drift
            fn(self, *args)

        repeating.handle = self.clock.at(start + period, tick, 1)
        return repeating

    def cancel(self, handle: Any) -> None:
        if isinstance(handle, Repeating):
            handle.cancelled = True
            handle = handle.handle
        self.clock.cancel(handle)

    def link(self, link_id: str) -> Any:
        try:
            return self._links[link_id]
        except KeyError:
            raise KeyError(f"application {self.name!r} has no link {link_id!r} "
                           f"(its links: {', '.join(self.links)})") from None
