"""The radio of a simulated modem: what it is receiving, what it is sending, and what collides.

This is the transducer of ns-3's UAN model (``UanTransducerHd``): it keeps the modem's transmit
window, the arrivals it is receiving and the interference it hears, and decides which arrivals
collide (DESIGN.md's timing model, step 4, and the error draw of step 5).  The medium only works out
*when* a frame reaches which radio (through the channel) and *how likely* it is lost (through the
error model), then hands each arrival to the receiver in one call, :meth:`Radio.arrive`.  The modem
above it never looks at arrivals: at the end of each one it is judging, the radio tells its host the
outcome with :meth:`RadioHost.heard`.

An arrival someone must judge (addressed to this radio, broadcast, or every arrival when the radio
``judges_all``: promiscuous modems and MACs that overhear) is an :class:`Arrival` in ``pending``;
any other is only interference, a ``(start, end)`` pair in ``noise`` that can spoil the judged ones.
Expired entries are dropped as the lists are walked (``noise`` once it has doubled since it was last
pruned), so each list stays within a small multiple of the number of frames on air at once: that
keeps an arrival O(1).

A static pair whose receiver does not judge the frame is not handed an arrival at all (``air.py``):
the radio gathers such quiet arrivals from the medium's record of the air (``air``) when it judges an
arrival (at its end: :meth:`_arrival_over`, :meth:`_sinr_over`) or senses the carrier (:meth:`busy`).
While the air holds no record (a sparse scene) none of this costs a call: a frame's path is as it was.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Protocol

from .frame import BROADCAST

if TYPE_CHECKING:
    import random

    from .air import Air
    from .clock import Clock
    from .errormodel import ErrorModel
    from .frame import Frame
    from .medium import Medium
    from .trajectories import PoseSource

OVERLAP_EPS = 1e-9
"""Arrivals must overlap by more than a nanosecond to collide: back-to-back frames computed along
different floating-point paths (t + τ + T versus (t + T) + τ) may otherwise "overlap" by one ulp."""


NOISE_MIN = 8
"""``noise`` is pruned once it holds this many more entries than twice what was still on air at the
last pruning: pruning then costs O(1) per arrival however many frames are on air at once."""


class RadioHost(Protocol):
    """What a radio tells the modem above it (the modem's side of the radio)."""

    id: str
    on_phy: Callable[..., Any] | None
    """An optional capability: set (not None) while an emulated modem above wants the PHY's doings; the
    radio then also calls :meth:`arrival_started` at each arrival's start (else nothing is scheduled)."""

    def arrival_started(self, frame: "Frame", start: float, end: float) -> None:
        """An arrival for this host begins at ``start`` (called only while :attr:`on_phy` is set)."""

    def heard(self, frame: "Frame", cause: str | None) -> None:
        """An arrival this radio judged has ended: ``cause`` is None (good), ``prop``, ``col``, ``mult``,
        or ``modulation`` (a modulation this radio does not decode)."""

    def unreachable(self, frame: "Frame", cause: str = "range") -> None:
        """A frame for this radio that it cannot judge: sent while it was out of the sender's range
        (``range``), while the sender or this radio had no pose (``no_pose``: a live vehicle whose first
        pose has not come, or a stale one dropped), or outside this radio's band (``band``)."""


class LossModel(Protocol):
    """What the medium hands with an arrival: the frame-loss probability on that path."""

    def per(self, d: float, size: int) -> float: ...


class SinrLossModel(LossModel, Protocol):
    """With ``collisions: sinr``: the path's received power and its PER with interference added."""

    def rx_power(self, d: float) -> float: ...

    def per_sinr(self, d: float, size: int, interference: float) -> float: ...


class Arrival:
    """One frame reaching one radio over ``[start, end]``; flags set as the radio learns more."""

    __slots__ = ("frame", "start", "end", "d", "error", "collided", "power", "interference", "parts", "loss",
                 "refused")

    def __init__(self, frame: "Frame", start: float, end: float, d: float):
        self.frame = frame
        self.start = start
        self.end = end
        self.d = d
        self.error = False
        self.collided = False
        self.power = 0.0  # collisions: sinr: received power, and the summed power of what overlaps it
        self.interference = 0.0
        self.parts: list[tuple[int, float]] | None = None  # collisions: sinr: (transmission seq, power) to add
        self.loss: "SinrLossModel | None" = None
        self.refused: str | None = None  # the receiver cannot decode it (e.g. ``modulation``): lost with this cause

    def __repr__(self) -> str:
        return f"Arrival({self.frame!r} [{self.start:.6f}, {self.end:.6f}] d={self.d:.3f})"


class Radio:
    """One modem's transducer on the medium.

    What the medium reads (the radio's identity on the channels, from the modem's configuration):
    ``address``, ``tx_channel``, ``rx_channel``, ``range_m`` (as a sender), ``pose`` (where its vehicle
    is), ``error`` (the receiving side's error model, as docs/channel-models.md decides), ``acoustic``
    and ``bitrate_bps`` (the modem's front end and bit rate: the transmit side of its paths, and its
    band as a receiver; ``path.py`` binds them), ``host`` (to find a modem by address), ``listens``
    (False for a modem another host serves: it only sends here) and ``judges_all`` (such a radio is
    handed every arrival: none is quiet for it, ``air.py``).  What the medium calls: :meth:`arrive`
    for every arrival, :meth:`arrive_refused` for one it cannot decode, :meth:`unreachable` for a frame
    addressed to it that cannot arrive; it sets ``air``, its record of the quiet arrivals this radio
    gathers when it judges or senses.  What the modem calls: :meth:`configure`,
    :meth:`transmit` and :meth:`busy`; it sets ``pose`` and ``judges_all``.
    """

    __slots__ = (
        "host", "medium", "clock", "rng",
        "address", "tx_channel", "rx_channel", "range_m", "pose", "error", "error_free", "half_duplex", "judges_all",
        "listens", "acoustic", "bitrate_bps",
        "tx_start", "tx_end", "pending", "noise", "_noise_cap", "capture", "air",
    )

    def __init__(self, host: RadioHost, medium: "Medium", clock: "Clock", rng: "random.Random"):
        self.host = host
        self.medium = medium
        self.clock = clock
        self.rng = rng  # the modem's own stream: one draw per judged arrival that may be lost
        self.address = -1
        self.tx_channel = self.rx_channel = ""
        self.range_m: tuple[float, float] = (0.0, float("inf"))
        self.pose: "PoseSource | Any" = None
        self.error: "ErrorModel | Any" = None
        self.error_free = True  # ``error`` is constant zero: no loss to compute, no draw
        self.half_duplex = True
        self.judges_all = False
        self.listens = True  # False: the modem is served by another host, whose own medium judges its arrivals
        self.acoustic: Any = None  # the modem's acoustic front end (physical.Acoustic), if it declares one
        self.bitrate_bps = 1000.0
        self.tx_start = float("-inf")
        self.tx_end = float("-inf")
        self.pending: list[Arrival] = []  # judged arrivals that may still be on air
        self.noise: list[tuple[float, float]] = []  # (start, end) of arrivals that only interfere
        self._noise_cap = NOISE_MIN  # prune ``noise`` when it grows past this
        self.capture = 0.0  # collisions: sinr: the capture ratio (linear); 0: strict overlap (the default)
        self.air: "Air | None" = None  # the medium's record of quiet arrivals (``air.py``), set when it lists the radios

    # -- the modem's side ----------------------------------------------------------------------

    def configure(self, address: int, tx_channel: str, rx_channel: str, range_m: tuple[float, float],
                  error: "ErrorModel", half_duplex: bool, acoustic: Any = None, bitrate_bps: float = 1000.0) -> None:
        """Take the modem's (new) parameters; the modem tells the medium that they changed."""
        self.acoustic = acoustic
        self.bitrate_bps = bitrate_bps
        self.address = address
        self.tx_channel = tx_channel
        self.rx_channel = rx_channel
        self.range_m = range_m
        self.error = error
        self.error_free = error.constant_zero
        self.half_duplex = half_duplex
        self.capture = error.capture if error.sinr else 0.0

    def transmit(self, frame: "Frame", t: float, duration: float) -> None:
        """Put ``frame`` on air from ``t`` for ``duration``: half duplex, it spoils what is arriving."""
        end = t + duration
        self.tx_start = t
        self.tx_end = end
        if self.half_duplex:
            for arrival in self.pending:
                if arrival.start < end - OVERLAP_EPS and arrival.end - OVERLAP_EPS > t:
                    arrival.collided = True
        self.medium.transmit(self, frame, t, duration)

    def busy(self, now: float) -> bool:
        """Carrier sense: something is arriving now, or this radio is transmitting."""
        if self.tx_start <= now < self.tx_end:
            return True
        for arrival in self.pending:
            if arrival.start <= now < arrival.end:
                return True
        for span in self.noise:
            if span[0] <= now < span[1]:
                return True
        air = self.air
        return air is not None and bool(air.records) and air.busy(self, now)

    # -- the medium's side ---------------------------------------------------------------------

    def arrive(self, frame: "Frame", t: float, start: float, end: float, d: float,
               loss: LossModel) -> Arrival | None:
        """``frame``, sent at ``t`` from ``d`` metres away, reaches this radio over ``[start, end]``;
        ``loss`` gives its loss probability on that path.

        An arrival this radio judges goes to :meth:`_judge` (and is returned); any other is only
        interference, kept as a span that may spoil what it judges (the common case, so it is handled
        right here)."""
        dst = frame.dst_addr
        if self.capture:
            return self._arrive_sinr(frame, t, start, end, d, loss)  # type: ignore[arg-type]
        if self.judges_all or dst == self.address or dst == BROADCAST:
            return self._judge(frame, t, start, end, d, loss)
        if self.pending:
            for other in self.pending:
                if other.start < end - OVERLAP_EPS and start < other.end - OVERLAP_EPS:
                    other.collided = True
        noise = self.noise
        noise.append((start, end))
        if len(noise) > self._noise_cap:
            noise = self.noise = [span for span in noise if span[1] > t]
            self._noise_cap = NOISE_MIN + 2 * len(noise)
        return None

    def arrive_refused(self, frame: "Frame", t: float, start: float, end: float, d: float, loss: LossModel,
                       cause: str) -> None:
        """An arrival this radio hears but cannot decode (``cause``: ``modulation``): it keeps the
        channel busy and spoils what it overlaps as any arrival does; one it judges ends lost with
        ``cause``, whatever else happened to it (``loss`` says PER 1, so nothing is drawn)."""
        arrival = self.arrive(frame, t, start, end, d, loss)
        if arrival is not None:
            arrival.refused = cause

    def _judge(self, frame: "Frame", t: float, start: float, end: float, d: float, loss: LossModel) -> Arrival:
        """Check the arrival against what this radio hears and its own transmission, draw its loss now
        (so draws follow the order of transmissions), and decide its outcome at its end."""
        arrival = Arrival(frame, start, end, d)
        live = []
        for other in self.pending:
            if other.end > t:
                live.append(other)
                if other.start < end - OVERLAP_EPS and start < other.end - OVERLAP_EPS:
                    other.collided = True
                    arrival.collided = True
        live.append(arrival)
        self.pending = live
        if not arrival.collided:
            for other_start, other_end in self.noise:  # 2-tuples: only collisions: sinr keeps powers
                if other_start < end - OVERLAP_EPS and start < other_end - OVERLAP_EPS:
                    arrival.collided = True
                    break
            if self.half_duplex and self.tx_end - OVERLAP_EPS > start and self.tx_start < end - OVERLAP_EPS:
                arrival.collided = True
        if not self.error_free:
            per = loss.per(d, frame.size)
            if per > 0.0 and (per >= 1.0 or self.rng.random() < per):
                arrival.error = True
        if self.host.on_phy is not None:  # an emulated modem reports RECVSTART
            self.clock.at(start, self.host.arrival_started, frame, start, end)
        self.clock.at(end, self._arrival_over, arrival)
        return arrival

    # -- collisions: sinr ------------------------------------------------------------------------

    def _arrive_sinr(self, frame: "Frame", t: float, start: float, end: float, d: float,
                     loss: SinrLossModel) -> Arrival | None:
        """An arrival under ``collisions: sinr``: instead of spoiling what it overlaps, it adds its
        received power to their interference (and theirs to its own, if judged).  The outcome is drawn
        at its end (:meth:`_sinr_over`), once every overlapping arrival is known.  The interference of
        an arrival is the sum of the powers of all arrivals that overlap it at any time (conservative:
        ns-3's UanPhyGen keeps the worst SINR seen during the reception)."""
        power = loss.rx_power(d)
        pending = self.pending
        dst = frame.dst_addr
        seq = self.air.seq if self.air is not None else 0
        if dst not in (self.address, BROADCAST) and not self.judges_all:  # not judged: only interference
            for other in pending:
                if other.start < end - OVERLAP_EPS and start < other.end - OVERLAP_EPS:
                    _add_part(other, seq, power)
            noise = self.noise
            noise.append((start, end, power, seq))
            if len(noise) > self._noise_cap:
                noise = self.noise = [span for span in noise if span[1] > t]
                self._noise_cap = NOISE_MIN + 2 * len(noise)
            return None
        arrival = Arrival(frame, start, end, d)
        arrival.power = power
        arrival.loss = loss
        parts = arrival.parts = []
        live = []
        for other in pending:
            if other.end > t:
                live.append(other)
                if other.start < end - OVERLAP_EPS and start < other.end - OVERLAP_EPS:
                    _add_part(other, seq, power)
                    arrival.interference += other.power
        live.append(arrival)
        self.pending = live
        for span in self.noise:
            if span[0] < end - OVERLAP_EPS and start < span[1] - OVERLAP_EPS:
                parts.append((span[3], span[2]))
        if self.half_duplex and self.tx_end - OVERLAP_EPS > start and self.tx_start < end - OVERLAP_EPS:
            arrival.collided = True
        self.clock.at(end, self._sinr_over, arrival)
        return arrival

    def _sinr_over(self, arrival: Arrival) -> None:
        """Capture: the arrival survives the overlap if its power is at least ``capture`` times the
        interference; its loss is then drawn at the SINR (noise plus interference).

        The interference is summed in the order the eager hand-out added it: the judged arrivals already
        on air when this one came (``interference`` so far), then every other part in the order of the
        transmissions (``parts``, with the quiet arrivals the medium's air record holds)."""
        interference = arrival.interference
        parts = arrival.parts or ()
        air = self.air
        if air is not None and air.records:
            quiet = air.powers(self, arrival.start, arrival.end, OVERLAP_EPS)
            if quiet:
                parts = sorted([*parts, *quiet])  # (seq, power): the seqs differ, powers are never compared
        for _, power in parts:
            interference += power
        arrival.interference = interference
        if interference > 0.0 and arrival.power < self.capture * interference:
            arrival.collided = True
        if not self.error_free:
            per = arrival.loss.per_sinr(arrival.d, arrival.frame.size, interference)  # type: ignore[union-attr]
            if per > 0.0 and (per >= 1.0 or self.rng.random() < per):
                arrival.error = True
        self._arrival_over(arrival, True)

    def unreachable(self, frame: "Frame", cause: str = "range") -> None:
        """A frame for this radio that cannot reach it (``range``: out of the sender's range;
        ``no_pose``: the sender or this radio has no position; ``band``: outside this radio's band)."""
        self.host.unreachable(frame, cause)

    def _arrival_over(self, arrival: Arrival, sinr: bool = False) -> None:
        """An arrival's end: its outcome to the host.  Quiet arrivals that overlapped it spoil it now
        (under ``collisions: sinr`` they were summed into its interference instead)."""
        air = self.air
        if air is not None and air.records and not (arrival.collided or sinr or arrival.refused is not None) \
                and air.overlaps(self, arrival.start, arrival.end, OVERLAP_EPS):
            arrival.collided = True
        if arrival.refused is not None:
            cause = arrival.refused
        elif arrival.error:
            cause = "mult" if arrival.collided else "prop"
        else:
            cause = "col" if arrival.collided else None
        self.host.heard(arrival.frame, cause)

    def __repr__(self) -> str:
        return f"Radio(addr={self.address} {self.tx_channel}->{self.rx_channel})"


def _add_part(arrival: Arrival, seq: int, power: float) -> None:
    """Power from transmission ``seq`` overlapped ``arrival`` (collisions: sinr), to be summed at its end."""
    if arrival.parts is None:  # (made before its radio took collisions: sinr)
        arrival.parts = [(seq, power)]
    else:
        arrival.parts.append((seq, power))
