"""What the models report as they run: the events of the trace, as calls.

The simulated modem and the MACs call an :class:`Observer` at every enqueue, drop, transmission,
delivery and loss.  ``hilgate.sim.recorder`` implements it (trace file, per-flow and per-link metrics);
tests use :class:`EventList` to look at exactly what happened.
"""

from __future__ import annotations

from typing import Any, Protocol


class Observer(Protocol):
    def enq(self, t: float, modem: Any, frame: Any) -> None: ...

    def drop(self, t: float, modem: Any, frame: Any, cause: str) -> None: ...

    def tx(self, t: float, modem: Any, frame: Any) -> None: ...

    def rx(self, t: float, modem: Any, frame: Any) -> None: ...

    def err(self, t: float, modem: Any, frame: Any, cause: str) -> None: ...

    def mac(self, t: float, modem: Any, frame: Any, ev: str, **fields: Any) -> None:
        """A MAC outcome: ``retx``, ``giveup``, ``backoff``, ``dup``…"""

    def add_flow(self, spec: Any) -> Any:
        """Where a scene's flow counts what it sends (``hilgate.sim.recorder.FlowStats``); None: nowhere."""


class NullObserver:
    def enq(self, t, modem, frame):
        pass

    def drop(self, t, modem, frame, cause):
        pass

    def tx(self, t, modem, frame):
        pass

    def rx(self, t, modem, frame):
        pass

    def err(self, t, modem, frame, cause):
        pass

    def mac(self, t, modem, frame, ev, **fields):
        pass

    def add_flow(self, spec):
        return None


class EventList:
    """Keeps every event as a tuple ``(t, ev, link, frame_id, cause_or_None)``; for tests."""

    def __init__(self) -> None:
        self.events: list[tuple[float, str, str, int, str | None]] = []
        self.kinds: dict[int, str] = {}
        self.fields: list[tuple[float, str, str, dict]] = []  # MAC events with their extra fields

    def _add(self, t, ev, modem, frame, cause=None):
        self.events.append((t, ev, modem.id, frame.id, cause))
        self.kinds[frame.id] = frame.kind

    def enq(self, t, modem, frame):
        self._add(t, "enq", modem, frame)

    def drop(self, t, modem, frame, cause):
        self._add(t, "drop", modem, frame, cause)

    def tx(self, t, modem, frame):
        self._add(t, "tx", modem, frame)

    def rx(self, t, modem, frame):
        self._add(t, "rx", modem, frame)

    def err(self, t, modem, frame, cause):
        self._add(t, "err", modem, frame, cause)

    def mac(self, t, modem, frame, ev, **fields):
        self._add(t, ev, modem, frame, fields.get("cause"))
        self.fields.append((t, ev, modem.id, fields))

    def add_flow(self, spec):
        return None

    def of(self, ev: str) -> list[tuple[float, str, str, int, str | None]]:
        return [e for e in self.events if e[1] == ev]
