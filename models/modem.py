"""The simulated modem: transmit FIFO in bytes, intrinsic delays and jitter, bitrate, its MAC and its radio.

This is DESIGN.md's timing model, steps 1, 2 and 6, with the MAC deciding when the head of the FIFO
goes to the PHY.  A frame leaves the FIFO when the MAC hands it to the PHY; from then until the end
of its transmission the PHY is busy.  What is on air (duplex, collisions, the error draw) is the
radio's (``radio.py``); the modem hears only the outcome of each arrival.  With ``mac: none`` that
gives exactly

    t_s = max(t0, t_free) + tx_delay + N(0, tx_jitter)   (extra delay never negative)
    delivery = t_e + rx_delay + N(0, rx_jitter)          (extra delay never negative)
"""

from __future__ import annotations

import json
import random
from collections import deque
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable

from .acoustic_ack import MODEM_ACK, Acknowledger
from .errormodel import NO_ERRORS, ErrorModel
from .frame import BROADCAST, DATA, Frame
from .mac import Mac, NoMac
from .observer import NullObserver, Observer
from .physical import Acoustic
from .radio import Radio

if TYPE_CHECKING:
    from .clock import Clock
    from .medium import Medium
    from .trajectories import PoseSource


@dataclass(frozen=True)
class ModemParams:
    """Everything that shapes a simulated modem's behaviour (the link keys of a scene)."""

    address: int
    tx_channel: str
    rx_channel: str
    bitrate_bps: float = 1000.0
    tx_delay_s: float = 0.0
    rx_delay_s: float = 0.0
    tx_jitter_s: float = 0.0
    rx_jitter_s: float = 0.0
    fifo_bytes: int = 500_000
    range_m: tuple[float, float] = (0.0, float("inf"))
    error: ErrorModel = field(default=NO_ERRORS)
    duplex: str = "half"
    promiscuous: bool = False
    ack_bytes: int = 6  # the modem's own ACK frame (acoustic_ack.py), for frames that ask for one
    ack_turnaround_s: float = 0.0  # end of a reception to its ACK on air
    acoustic: Any = None  # the acoustic front end (physical.Acoustic), whatever ``error`` is: path.py binds it


@dataclass
class LinkStats:
    tx_packets: int = 0
    rx_packets: int = 0
    fifo_drops: int = 0
    fifo_peak_bytes: int = 0
    lost: dict[str, int] = field(default_factory=dict)  # arrivals for this modem lost, by cause (prop, no_pose…)


class SimModem:
    """One simulated modem: FIFO, intrinsic delays, MAC, and its :class:`~hilgate.models.radio.Radio`
    on a :class:`~hilgate.models.medium.Medium`.  To its MAC it is a
    :class:`~hilgate.models.mac.MacHost`; to its radio a :class:`~hilgate.models.radio.RadioHost`."""

    def __init__(
        self,
        link_id: str,
        vehicle: str,
        pose: "PoseSource",
        params: ModemParams,
        clock: "Clock",
        medium: "Medium",
        rng: random.Random,
        observer: Observer | None = None,
        mac: Mac | None = None,
    ):
        self.id = link_id
        self.json_id = json.dumps(link_id)
        self.vehicle = vehicle
        self.clock = clock
        self.medium = medium
        self.rng = rng
        self.observer: Observer = observer or NullObserver()
        self.stats = LinkStats()
        self.on_deliver: Callable[["Frame"], Any] | None = None  # hands a good frame up (the backend)
        self.on_idle: Callable[[], Any] | None = None  # FIFO empty and PHY free again (GLI READY)
        # What the PHY does, for an emulated modem that reports it (SENDSTART, RECVSTART…): called as
        # on_phy(kind, frame, start, end, cause) with kind "tx", "rx_start" or "rx_end"; None costs nothing.
        self.on_phy: Callable[..., Any] | None = None
        self.fifo: deque[Frame] = deque()
        self.queued_bytes = 0
        self.phy_busy = False
        self.closed = False
        self.mac: Mac | None = None
        self.direct = False  # the MAC is NoMac itself: its steps done here (set_mac)
        self.radio = Radio(self, medium, clock, rng)
        self.acks = Acknowledger(self)
        self.radio.pose = pose
        self.configure(params)
        self.set_mac(mac or NoMac())
        medium.attach(self.radio)

    def configure(self, params: ModemParams) -> None:
        """Take new parameters in place (a scene reload); frames in the FIFO are kept."""
        self.params = params
        self.bitrate = float(params.bitrate_bps)
        self.tx_delay = params.tx_delay_s
        self.rx_delay = params.rx_delay_s
        self.tx_jitter = params.tx_jitter_s
        self.rx_jitter = params.rx_jitter_s
        self.fifo_bytes = params.fifo_bytes
        self.promiscuous = params.promiscuous
        self.radio.configure(params.address, params.tx_channel, params.rx_channel, params.range_m, params.error,
                             params.duplex == "half", params.acoustic, self.bitrate)
        if self.mac is not None:  # (None only while __init__ configures before set_mac)
            self.radio.judges_all = self.promiscuous or self.mac.hears_all
            self.medium.topology_changed()

    def set_mac(self, mac: Mac) -> None:
        self.mac = mac
        mac.attach(self)
        self.radio.judges_all = self.promiscuous or mac.hears_all
        # ``mac: none`` exactly (not a subclass, which may change what it does): the modem does the MAC's
        # three steps itself (the head of the FIFO on air when the PHY is free, after a frame is queued
        # and after a transmission; a good frame for it delivered), in the same order, so the trace is
        # the same, without the five calls per frame into a MAC that adds nothing.
        self.direct = type(mac) is NoMac
        self.medium.topology_changed()  # a radio that judges every frame is handed every arrival (air.py)

    # What the radio holds, read through the modem (MACs, the trace, the emulators).

    @property
    def address(self) -> int:
        return self.radio.address

    @property
    def tx_channel(self) -> str:
        return self.radio.tx_channel

    @property
    def rx_channel(self) -> str:
        return self.radio.rx_channel

    @property
    def range_m(self) -> tuple[float, float]:
        return self.radio.range_m

    @property
    def error(self) -> ErrorModel:
        return self.radio.error

    @property
    def pose(self) -> "PoseSource":
        return self.radio.pose

    def set_pose(self, pose: "PoseSource") -> None:
        self.radio.pose = pose
        self.medium.topology_changed()

    # -- frames ---------------------------------------------------------------------------------

    def new_frame(self, dst_link: str, dst_addr: int, size: int, flow: Any = None, app_frame: Any = None,
                  kind: str = DATA, ref: "Frame | None" = None) -> Frame:
        """The one way to make a frame this modem sends: the next id of the medium, stamped now.

        ``dst_link`` is the receiver's link id for the trace (``"*"`` for broadcast), ``dst_addr`` the
        address receivers match; ``flow`` the statistics of the flow that offered it, ``app_frame`` an
        application's frame; MACs make their control frames with another ``kind`` serving ``ref``."""
        frame = Frame(next(self.medium.frame_ids), self.id, dst_link, dst_addr, size, self.clock.now(), flow,
                      app_frame, kind, ref)
        frame.src_addr = self.radio.address
        return frame

    # -- from the application ------------------------------------------------------------------

    def send(self, frame: "Frame") -> bool:
        """Offer a frame to the transmit FIFO; False if it did not fit (dropped, cause ``fifo``)."""
        t = self.clock.now()
        if self.queued_bytes + frame.size > self.fifo_bytes:
            self.stats.fifo_drops += 1
            self.observer.drop(t, self, frame, "fifo")
            return False
        frame.src_addr = self.radio.address
        self.fifo.append(frame)
        self.queued_bytes += frame.size
        if self.queued_bytes > self.stats.fifo_peak_bytes:
            self.stats.fifo_peak_bytes = self.queued_bytes
        self.observer.enq(t, self, frame)
        if not self.direct:
            self.mac.on_enqueue()
        elif not self.phy_busy:  # (NoMac's on_enqueue: the head of the FIFO on air)
            head = self.fifo.popleft()
            self.queued_bytes -= head.size
            self.transmit(head)
        return True

    # -- what a MAC may use (MacHost) -----------------------------------------------------------

    def set_address(self, address: int) -> None:
        """The modem answers to ``address`` from now on (an emulated modem's ``AT!AL``): frames it sends
        carry it, frames to it arrive; frames already queued keep the source they were given."""
        self.radio.address = address
        self.medium.topology_changed()

    def set_band(self, band_khz: tuple[float, float]) -> None:
        """The modem sends and listens in ``band_khz`` from now on (an emulated modem's channel: an M64's
        ``wcs``); its acoustic front end keeps its level and modulation (a link without one gets a band
        alone).  Bands that do not overlap never meet: no arrival, no collision (``path.py``)."""
        band = (float(band_khz[0]), float(band_khz[1]))
        acoustic = self.params.acoustic
        if acoustic is not None and tuple(acoustic.band_khz) == band:
            return
        acoustic = Acoustic(band, 0.0) if acoustic is None else replace(acoustic, band_khz=band)
        self.configure(replace(self.params, acoustic=acoustic))

    def withdraw(self, wanted: Callable[["Frame"], bool], cause: str) -> int:
        """Take the queued frames ``wanted`` says out of the FIFO (an emulated modem's ``ATZ``): each is
        traced as a drop with ``cause``.  Frames the MAC holds or already on air go on.  Returns how many."""
        t = self.clock.now()
        kept: deque[Frame] = deque()
        taken = 0
        for frame in self.fifo:
            if wanted(frame):
                self.queued_bytes -= frame.size
                self.observer.drop(t, self, frame, cause)
                taken += 1
            else:
                kept.append(frame)
        self.fifo = kept
        if taken:
            self.check_idle()
        return taken

    def fifo_pop(self) -> "Frame":
        frame = self.fifo.popleft()
        self.queued_bytes -= frame.size
        return frame

    def transmit(self, frame: "Frame") -> None:
        """Put ``frame`` on air after the intrinsic delay and jitter; the PHY is busy until it ends."""
        self.phy_busy = True
        extra = self.tx_delay
        if self.tx_jitter:
            extra += self.rng.gauss(0.0, self.tx_jitter)
        if extra > 0.0:
            self.clock.at(self.clock.now() + extra, self._on_air, frame)
        else:
            self._on_air(frame)

    def airtime(self, size: int) -> float:
        return size * 8.0 / self.bitrate

    def tau_at(self, range_m: float) -> float:
        """Propagation delay to ``range_m`` metres on this modem's transmit channel."""
        return self.medium.channels[self.radio.tx_channel].propagation.delay(range_m)

    def deliver(self, frame: "Frame") -> None:
        """Hand a good frame to the application after the rx delay and jitter."""
        extra = self.rx_delay
        if self.rx_jitter:
            extra += self.rng.gauss(0.0, self.rx_jitter)
        if extra > 0.0:
            self.clock.at(self.clock.now() + extra, self._deliver_now, frame)
        else:
            self._deliver_now(frame)

    def channel_busy(self) -> bool:
        """Carrier sense: something is arriving at this modem now, or it is transmitting."""
        return self.radio.busy(self.clock.now())

    def control_frame(self, kind: str, size: int, dst_addr: int, dst: str, ref: "Frame") -> "Frame":
        """A MAC frame (ack, rts, cts…) serving ``ref``: its bytes count as ``ref``'s flow's on-air bytes."""
        return self.new_frame(dst, dst_addr, size, flow=ref.flow, kind=kind, ref=ref)

    def consume(self, frame: "Frame") -> None:
        """A good MAC frame for this modem, used by the MAC itself: traced as ``rx``, not delivered."""
        self.observer.rx(self.clock.now(), self, frame)

    @property
    def idle(self) -> bool:
        """Nothing to send: FIFO empty, PHY free, and the MAC holds no frame (e.g. awaiting its ACK)."""
        return not self.phy_busy and not self.fifo and not self.mac.holding and not self.acks.waiting  # (acks.busy, written out)

    def check_idle(self) -> None:
        """Tell the GLI (READY) if the modem just became idle; MACs call it when they let go of a frame."""
        if self.on_idle is not None and self.idle:
            self.on_idle()

    # -- what the acknowledgements use (acoustic_ack.py) ------------------------------------------

    def requeue(self, frame: "Frame") -> None:
        """Put a frame whose ACK did not come back at the head of the FIFO again (its retransmission)."""
        if self.closed:
            return
        self.fifo.appendleft(frame)
        self.queued_bytes += frame.size
        if self.queued_bytes > self.stats.fifo_peak_bytes:
            self.stats.fifo_peak_bytes = self.queued_bytes
        self.mac.on_enqueue()

    def transmit_now(self, frame: "Frame") -> None:
        """Put the modem's own ACK on air now, bypassing FIFO, MAC and tx delay (the PHY is free)."""
        self.phy_busy = True
        self._on_air(frame)

    # -- inside the modem ---------------------------------------------------------------------

    def close(self) -> None:
        """Leave the medium (the link was removed or given a real modem); queued frames are dropped
        and reported with cause ``closed``, frames already on air finish as the physics says."""
        if self.closed:
            return
        self.closed = True
        self.on_deliver = None
        self.on_idle = None
        self.acks.forget()
        t = self.clock.now()
        while self.fifo:
            frame = self.fifo_pop()
            self.stats.fifo_drops += 1
            self.observer.drop(t, self, frame, "closed")
        self.medium.detach(self.radio)

    def _on_air(self, frame: "Frame") -> None:
        if self.closed:  # closed during its tx delay: it never went on air, and says so
            self.stats.fifo_drops += 1
            self.observer.drop(self.clock.now(), self, frame, "closed")
            return
        t = self.clock.now()
        duration = frame.size * 8.0 / self.bitrate if frame.airtime is None else frame.airtime
        self.stats.tx_packets += 1
        self.observer.tx(t, self, frame)
        self.radio.transmit(frame, t, duration)
        if self.on_phy is not None:
            self.on_phy("tx", frame, t, t + duration, None)
        self.clock.at(t + duration, self._off_air, frame)

    def _off_air(self, frame: "Frame") -> None:
        self.phy_busy = False
        if frame.ack is not None and self.acks.wants_ack(frame):
            self.acks.sent(frame, self.clock.now())
        owed = self.acks.next_owed() if self.acks.owed else None
        if owed is not None and not self.closed:
            self.transmit_now(owed)  # an ACK that came due while the PHY was busy goes first
        if not self.direct:
            self.mac.on_tx_done(frame)
        elif not self.phy_busy and self.fifo:  # (NoMac's on_tx_done: the next frame on air)
            self.transmit(self.fifo_pop())
        self.check_idle()

    # -- from the radio (RadioHost) -------------------------------------------------------------

    def heard(self, frame: "Frame", cause: str | None) -> None:
        """An arrival the radio judged has ended, good (``cause`` None) or lost."""
        address = self.radio.address
        addressed = frame.dst_addr == address or frame.dst_addr == BROADCAST or self.promiscuous
        if self.closed:  # the link went (removed, or given a real modem) while the frame was arriving
            if addressed and frame.kind == DATA:
                self._lost(frame, "closed")
            return
        if cause is not None and addressed:
            self._lost(frame, cause)
        if addressed and self.on_phy is not None and frame.kind != MODEM_ACK:  # (an ACK: no RECVEND)
            self.on_phy("rx_end", frame, None, self.clock.now(), cause)
        if frame.kind == MODEM_ACK:  # the modem's own: never a MAC's business
            if cause is None and frame.dst_addr == address:
                self.acks.heard_ack(frame)
            return
        if cause is None and frame.ack is not None and frame.dst_addr == address and frame.kind == DATA:
            if self.acks.heard_data(frame) and frame.app_frame is None:
                return  # a flow's duplicate: traced, not delivered (an application's is, as on a real modem)
        if self.direct:
            if cause is None and addressed:  # (NoMac's on_frame; deliver's rx delay only if it has one)
                if self.rx_delay or self.rx_jitter:
                    self.deliver(frame)
                else:
                    self._deliver_now(frame)
        elif addressed or self.mac.hears_all:
            self.mac.on_frame(frame, cause, addressed)

    def arrival_started(self, frame: "Frame", start: float, end: float) -> None:
        """The radio began to hear ``frame`` (only scheduled while someone watches the PHY)."""
        if not self.closed and self.on_phy is not None:
            self.on_phy("rx_start", frame, start, end, None)

    def unreachable(self, frame: "Frame", cause: str = "range") -> None:
        """A frame for this modem that it cannot judge (``range``: out of the sender's range; ``no_pose``:
        the sender or this modem had no position; ``band``: outside this modem's band): traced and counted
        with that cause, never silent."""
        self._lost(frame, cause)

    def _lost(self, frame: "Frame", cause: str) -> None:
        lost = self.stats.lost
        lost[cause] = lost.get(cause, 0) + 1
        self.observer.err(self.clock.now(), self, frame, cause)

    def _deliver_now(self, frame: "Frame") -> None:
        self.stats.rx_packets += 1
        self.observer.rx(self.clock.now(), self, frame)
        if self.on_deliver is not None:
            self.on_deliver(frame)

    def __repr__(self) -> str:
        return f"SimModem({self.id!r} addr={self.address})"
