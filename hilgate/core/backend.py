"""What a link id is routed to: one interface for simulated modems and real modem drivers.

The router talks to a backend only through :class:`Backend`; adding a modem type means adding its
driver module in ``drivers/`` and one row in the driver table (:mod:`hilgate.drivers.table`), not
touching the router.  A backend outlives nothing: on a reload that changes the backend kind, the
router closes the old one and opens the new one behind the same GLI endpoints.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

from .packets import PacketClass


@dataclass
class AppFrame:
    """A frame from an application, on its way to another: the real packet of the sender's class
    (its length is the size on air) plus what the receivers need to rebuild theirs."""

    real: bytes
    payload: bytes
    packet: PacketClass
    seq: int
    src: int
    dst: int
    t0: float = 0.0
    meta: dict[str, Any] | None = None  # what an emulated modem needs to print it (IM, burst, ack…)
    lateness: float = 0.0  # the loop was this late reading it: t0 may be up to this much after the send
    on_delivered: Callable[["AppFrame", Any], Any] | None = field(default=None, repr=False)
    ack_retries: int | None = None  # the simulated modem acknowledges it on the channel, retrying so often
    on_acknowledged: Callable[["AppFrame", bool, "float | None"], Any] | None = field(default=None, repr=False)
    """``(frame, delivered, one_way_tau_s)`` when its acknowledgement came back or the last retry failed."""
    airtime_s: float | None = None
    """Seconds on air when the sending modem decides it (a Micro-Modem's rate), not the link's bit rate."""
    pkt: int | None = None
    """The id of the frame on air that brought it (the trace's ``pkt``), once a simulated modem delivered
    it: the GLI's losses on delivery name it, as the medium's do."""
    on_dropped: Callable[["AppFrame", str], Any] | None = field(default=None, repr=False)
    """``(frame, cause)`` when the backend drops it before the air (a full FIFO, a modem down): a sender
    that promised its application a fate (a UnetStack door's ``DatagramFailureNtf``) keeps the promise."""


@dataclass(frozen=True)
class PhyEvent:
    """What a simulated modem's PHY did, for an emulated modem that reports it (``AT@ZX1``): ``kind`` is
    ``tx`` (a transmission over [start, end]), ``rx_start`` (an arrival for this modem begins; it ends
    at ``end``) or ``rx_end`` (it ended at ``end``: good when ``cause`` is None, else lost by it).
    ``frame`` is the application's frame on air (None for background traffic and MAC frames)."""

    kind: str
    frame: AppFrame | None
    size: int
    src: int
    dst: int
    start: float | None
    end: float
    cause: str | None = None


class Backend(ABC):
    """What the router asks of every backend.  The optional capabilities (a simulated modem has them, a
    real modem's driver not yet) are declared here with the answer of a backend that lacks them, so the
    router asks every backend the same way and never looks a method up by name."""

    kind = "?"

    def __init__(self) -> None:
        self.on_receive: Callable[[AppFrame], Any] | None = None
        self.on_idle: Callable[[], Any] | None = None
        self.on_state: Callable[[str], Any] | None = None

    @property
    @abstractmethod
    def state(self) -> str:
        """``up``, ``down`` or ``starting``."""

    @property
    @abstractmethod
    def idle(self) -> bool:
        """Nothing queued or on air: the GLI says READY."""

    def admit(self, frame: AppFrame) -> None:
        """Raise :class:`~hilgate.core.packets.PacketError` if the modem would refuse ``frame`` (too large
        for it): called before :meth:`send`, when the application sends, so the application is told at
        once, by a real modem's driver and a simulated link alike."""

    @abstractmethod
    def send(self, frame: AppFrame) -> bool:
        """Queue a frame for transmission; False if it was refused (and counted as dropped)."""

    @abstractmethod
    def status(self) -> dict[str, Any]:
        """``tx_packets``, ``rx_packets``, ``drops``, ``fifo_bytes`` for ``hilgate status``."""

    def close(self) -> None:
        """Release the modem; queued frames are reported dropped."""

    # -- optional capabilities: the defaults are those of a backend without them ----------------------

    sim_modem: Any = None
    """The simulated modem behind the link (``models.modem.SimModem``), None for a real modem: air time,
    propagation and receptions that an emulated modem reports come from it."""

    everyone_in_range = False
    """A frame from an application reaches every modem in range whatever its destination (a simulated link
    whose packet class carries no address on air and that has no MAC: ``addressing: auto``)."""

    addressed_only = False
    """A frame reaches only the address it carries, and the scene says who has which (a simulated link not
    ``everyone_in_range``): the link traces a frame to an address nobody has as lost (``no_receiver``)."""

    def rebind(self, modem: Any, everyone_in_range: bool, limits: Any) -> bool:
        """A reload changed the link in place: go on with the scene's new simulated ``modem``, addressing and
        ``limits``; False: this backend has no simulated modem to change."""
        return False

    def set_address(self, address: int) -> bool:
        """Answer to ``address`` from now on (an emulated modem's ``AT!AL``); False: this backend cannot."""
        return False

    def withdraw(self, frames: list[AppFrame], cause: str) -> int:
        """Take frames sent earlier back out of the queue (``ATZ``); how many were still there."""
        return 0

    def watch_phy(self, listener: Callable[[PhyEvent], Any] | None) -> None:
        """Report what the PHY does to ``listener`` (None: stop); a backend without a simulated PHY
        reports nothing."""

    def set_band(self, band_khz: tuple[float, float]) -> bool:
        """Send and listen in ``band_khz`` from now on (an emulated M64's channel); False: this backend
        cannot."""
        return False


class QueuedBackend(Backend):
    """What every real modem driver shares: a bounded queue of frames (kept while the modem is down,
    dropped with a cause beyond ``queue_frames``), its counters, and its ``link`` state in the trace,
    with the reason it is down (the port's one line: cannot open, lost) for ``hilgate status``."""

    def __init__(self, link_id: str, scheduler: Any, trace: Callable[[dict], Any], queue_frames: int):
        super().__init__()
        self.link_id = link_id
        self.scheduler = scheduler
        self.trace = trace
        self.queue_frames = queue_frames
        self.queue: deque[AppFrame] = deque()
        self.tx_packets = self.rx_packets = self.drops = 0
        self._state = "starting"
        self.reason: str | None = None

    @property
    def state(self) -> str:
        return self._state

    def send(self, frame: AppFrame) -> bool:
        if len(self.queue) >= self.queue_frames:
            self.drop(frame, "queue_full" if self._state == "up" else "down")
            return False
        self.queue.append(frame)
        self.pump()
        return True

    @abstractmethod
    def pump(self) -> None:
        """Start sending the head of the queue if the modem can take it."""

    def event(self, ev: str, **fields: Any) -> None:
        self.trace({"t": round(self.scheduler.now(), 9), "ev": ev, "link": self.link_id, **fields})

    def drop(self, frame: AppFrame, cause: str) -> None:
        self.drops += 1
        self.event("drop", dst=frame.dst, size=len(frame.real), cause=cause)
        if frame.on_dropped is not None:
            frame.on_dropped(frame, cause)

    def set_state(self, state: str, reason: str | None = None) -> None:
        """``reason``: why the link is down (kept until the next state), None otherwise."""
        self.reason = reason
        if state != self._state:
            self._state = state
            self.event("link", state=state, **({"reason": reason} if reason else {}))
            if self.on_state is not None:
                self.on_state(state)

    def status(self) -> dict[str, Any]:
        return {"tx_packets": self.tx_packets, "rx_packets": self.rx_packets, "drops": self.drops,
                "fifo_bytes": sum(len(f.real) for f in self.queue), "reason": self.reason}

    def close(self) -> None:
        while self.queue:
            self.drop(self.queue.popleft(), "closed")
