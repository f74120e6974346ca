"""The MAC hook of the simulated modem, and the protocol that does nothing (``mac: none``).

A MAC sits between the modem's transmit FIFO and its PHY.  It is *told*:

- ``on_enqueue()``: the application (or a flow) put a frame in the FIFO;
- ``on_tx_done(frame)``: the PHY finished putting ``frame`` on air;
- ``on_frame(frame, cause, addressed)``: an arrival ended at this modem; ``cause`` is None for a good
  frame, else ``"prop"``, ``"col"``, ``"mult"`` or ``"modulation"`` (a modulation this modem does not
  decode: it heard the frame, as interference, but cannot read it); ``addressed`` says whether it was meant for this
  modem (its address, broadcast, or the modem is promiscuous).  Only frames for this modem are
  reported unless the MAC sets ``hears_all`` (to overhear RTS/CTS, for example).
- timers it set itself fire (plain callbacks through ``modem.clock``).

It *may* use its modem, ``self.modem``, through :class:`MacHost` and nothing else; the built-in
protocols do exactly that (``tests/test_radio_mac_host.py`` checks it).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import OrderedDict, deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

if TYPE_CHECKING:
    import random

    from .clock import Clock
    from .frame import Frame
    from .observer import Observer


class MacHost(Protocol):
    """What a MAC may use of its modem: the whole MAC ↔ modem interface.

    A MAC needs no more to decide when frames go on air; it never reaches the medium, the radio or
    the modem's other parts, so a MAC runs unchanged on any host that offers these."""

    address: int
    """This modem's address (what ``frame.dst_addr`` is compared with)."""
    fifo: deque[Frame]
    """The transmit FIFO, to look at (take frames only with :meth:`fifo_pop`)."""
    phy_busy: bool
    """True from :meth:`transmit` until ``on_tx_done`` (intrinsic delay and air time)."""
    clock: Clock
    """Timers: ``clock.now()``, ``clock.at(t, fn, *args)`` → handle, ``clock.cancel(handle)``."""
    rng: random.Random
    """The modem's own seeded random stream, so backoffs are reproducible."""
    observer: Observer
    """``observer.mac(t, modem, frame, ev, **fields)`` traces MAC outcomes (``retx``, ``giveup``,
    ``backoff``, ``dup``)."""
    tx_delay: float
    """The modem's intrinsic transmit delay (s), for sizing slots and timeouts."""
    range_m: tuple[float, float]
    """The sender's range ``[min, max]`` in metres."""

    def fifo_pop(self) -> Frame:
        """Take the head of the FIFO (the frame then belongs to the MAC)."""

    def transmit(self, frame: Frame) -> None:
        """Put a frame on air after the modem's intrinsic delay and jitter."""

    def deliver(self, frame: Frame) -> None:
        """Hand a good frame up to the application (after the rx delay)."""

    def consume(self, frame: Frame) -> None:
        """Trace a good control frame as received; it is not delivered up."""

    def channel_busy(self) -> bool:
        """Carrier sense: true while something arrives or the modem transmits."""

    def control_frame(self, kind: str, size: int, dst_addr: int, dst: str, ref: Frame) -> Frame:
        """Make an ACK/RTS/CTS of ``size`` bytes for ``dst_addr`` (link id ``dst``) that serves ``ref``."""

    def check_idle(self) -> None:
        """Tell the GLI the modem may be idle again (call it after letting go of a held frame)."""

    def airtime(self, size: int) -> float:
        """Seconds on air for ``size`` bytes at the modem's bitrate."""

    def tau_at(self, range_m: float) -> float:
        """Propagation delay to ``range_m`` metres on the modem's transmit channel."""


@dataclass(frozen=True)
class Param:
    """One scene parameter of a MAC: ``kind`` is number, integer, pair (of numbers) or boolean;
    a ``default`` of None means the MAC computes it from the modem when it is not given."""

    kind: str
    default: Any = None
    minimum: float | None = None
    maximum: float | None = None
    doc: str = ""


class Mac:
    """Base class of every MAC protocol; the defaults are those of ``mac: none``.

    ``PARAMETERS`` declares the scene keys the protocol takes (besides ``protocol``); the scene
    loader validates them and passes them to the constructor as keyword arguments."""

    name = "none"
    hears_all = False
    PARAMETERS: ClassVar[dict[str, Param]] = {}
    holding = False
    """True while the MAC has taken a frame from the FIFO and is not done with it (awaiting its ACK,
    backing off…): the GLI says BUSY until it lets go (and calls ``modem.check_idle()``)."""

    def __init__(self, **params: Any):
        if params:
            raise TypeError(f"mac {self.name!r} takes no parameters, got {', '.join(sorted(params))}")
        self.modem: MacHost | None = None

    def attach(self, modem: MacHost) -> None:
        self.modem = modem

    def on_enqueue(self) -> None:
        self._send_next()

    def on_tx_done(self, frame: "Frame") -> None:
        self._send_next()

    def on_frame(self, frame: "Frame", cause: str | None, addressed: bool) -> None:
        if cause is None and addressed:
            self.modem.deliver(frame)

    def _send_next(self) -> None:
        modem = self.modem
        if not modem.phy_busy and modem.fifo:
            modem.transmit(modem.fifo_pop())

    @classmethod
    def check(cls, modem: Any, params: dict[str, Any]) -> str | None:
        """Whether these parameters work for a modem with these ``ModemParams`` (checked when the scene
        loads, so a problem is reported with its file and line); None if they do, else why not."""
        return None


class Duplicates:
    """Remembers the last frames delivered, so that a retransmission (its ACK was lost) is delivered
    once; ``seen`` answers and remembers in one step."""

    def __init__(self, size: int = 4096):
        self.size = size
        self._recent: OrderedDict[tuple[str, int], None] = OrderedDict()

    def seen(self, frame: "Frame") -> bool:
        key = (frame.src_link, frame.id)
        if key in self._recent:
            return True
        self._recent[key] = None
        if len(self._recent) > self.size:
            self._recent.popitem(last=False)
        return False


class HoldingMac(Mac, ABC):
    """A MAC that takes one frame from the FIFO at a time and holds it until it is acknowledged or given
    up (CS-ALOHA, S-FAMA): the frame held and its attempts, the one timer it waits on, the frames it
    delivered (a retransmission is delivered once), and the farthest receiver (``max_range_m``, else
    the modem's range) that its timings are sized for."""

    def __init__(self, max_range_m: float | None, max_retries: int):
        super().__init__()
        self.max_range_m = max_range_m
        self.max_retries = max_retries
        self.state = "idle"
        self.current: Frame | None = None
        self.attempts = 0
        self.timer: Any = None
        self.duplicates = Duplicates()

    @property
    def holding(self) -> bool:
        return self.current is not None

    def _done(self) -> None:
        """The held frame is acknowledged or given up: let it go, take the next, say so if idle."""
        self.current = None
        self.state = "idle"
        if self.timer is not None:
            self.modem.clock.cancel(self.timer)
            self.timer = None
        self._next()
        self.modem.check_idle()

    @abstractmethod
    def _next(self) -> None:
        """Take the next frame of the FIFO, if any, and start on it as the protocol does."""

    def max_range(self, remedy: str) -> float:
        """The farthest receiver; a ValueError saying ``remedy`` if it is unlimited (no timing fits)."""
        max_range = self.max_range_m if self.max_range_m is not None else self.modem.range_m[1]
        if max_range == float("inf"):
            raise ValueError(f"{self.name}: {remedy} (the modem's range is unlimited)")
        return max_range


class NoMac(Mac):
    """Transmit the head of the FIFO as soon as the PHY is free: the timing rule of DESIGN.md exactly."""
