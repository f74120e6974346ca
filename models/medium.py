"""Who hears whom, when, and how likely it survives: channels, propagation, range, error model.

For one transmission the medium walks the sending radio's *neighbours* (every radio listening on
the sender's transmit channel) once.  For each it works out, through the channel, whether the frame
reaches it and over which interval, and hands it the arrival in one call (:meth:`Radio.arrive`,
with the path's loss probability from the error model); the receiving radio keeps what it hears and
decides collisions (``radio.py``).  Distances between vehicles that never move, and the loss
probability on such a path, are computed once per pair; that is what keeps the hot path O(1) per
arrival.

The lists a transmission walks are the neighbour index's (``neighbours.py``, rebuilt when the topology
changes); the medium keeps the caches asked per transmission (out-of-range addressees, the moving grid,
pairs asked for their delay alone).

With a limited range, a transmission visits only modems that can be in range: static pairs beyond it
are never listed (the lists are built from a grid of static positions, cells as wide as the range),
and a sender with many moving neighbours finds them through a grid of where they were a moment ago,
widened by how far their top speed can have taken them since.  Both keep the list order, so traces
are the same as with a full scan; the work per transmission no longer grows with the number of modems.

In a dense scene most arrivals are judged by nobody: a static pair whose receiver does not judge the
frame (not its addressee, not a broadcast, not a promiscuous or overhearing receiver) is **quiet**. It
is counted, not listed; a transmission is recorded once per channel (``air.py``) and hands an arrival
only to the quiet receivers that judge it; the others gather its interference when they need it.  The
outcome is the same as handing every arrival at once (``lazy = False``, kept as the tests' oracle).

Each pair's loss model is bound once, when the pair is listed (``path.py``: the receiver's error model
with the sender's front end and bit rate).  A receiver that refuses a sender (bands that do not overlap:
it hears nothing; a modulation it does not decode: interference only) leaves that pair off the fast path,
so only such pairs pay for the check.

The arithmetic is DESIGN.md's "timing and loss model", step 3 (and the PER of step 5).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Iterable

from .air import Air, Quiet
from .frame import BROADCAST
from .neighbours import QUIET_MIN, Neighbours, _cell, _cell_size, _near, _Neighbour, _Roaming, quiet_index
from .propagation import Propagation
from .propagations import PROPAGATIONS, implied

NO_POSE = "no_pose"
"""The cause of a frame that cannot be judged because the sender or a receiver has no position (a live
vehicle before its first pose, a stale one dropped): traced at each radio that would have judged it."""

if TYPE_CHECKING:
    from .clock import Clock
    from .frame import Frame
    from .radio import Radio


@dataclass(frozen=True)
class Channel:
    """A shared medium.  Its ``propagation`` gives every path's delay and loss model (``propagation.py``),
    made by the model the channel names (``model``, the scene's ``propagation:``; ``propagations.py``): by
    default a :class:`~.propagation.StraightLine` at ``speed_mps`` after ``min_delay_s``."""

    name: str
    speed_mps: float
    min_delay_s: float = 0.0
    water: Any = None
    """The channel's water (``environment.Water``) when the scene gives one: BELLHOP's fields then
    decide every path's delay and loss (its propagation becomes a ``bellhop_fields.BellhopChannel``
    once the fields are ready: ``hilgate.channel.prepare``)."""
    propagation: Propagation = field(default=None, compare=False)  # type: ignore[assignment]  # (None: the model's)
    model: str = ""
    """The name of its propagation model (``propagations.PROPAGATIONS``); "": the one its water implies."""

    def __post_init__(self) -> None:
        if not self.model:
            object.__setattr__(self, "model", implied(self.water))
        if self.propagation is None:
            object.__setattr__(self, "propagation", PROPAGATIONS[self.model].make(self))


class Medium:
    """All channels of a scene and every radio attached to them."""

    def __init__(self, clock: "Clock", channels: Iterable[Channel]):
        self.clock = clock
        self.channels = {c.name: c for c in channels}
        self.radios: list[Radio] = []
        self.frame_ids = itertools.count(1)
        self.arrivals = 0
        self._neighbours: dict[Radio, list[_Neighbour]] = {}
        self._unreachable: dict[Radio, dict[int, tuple[Radio, ...]]] = {}
        self._by_address: dict[int, list[Radio]] = {}  # radios by address, in attachment order
        self._roam: dict[Radio, _Roaming] = {}
        self._order: dict[Radio, int] = {}
        self._snap: tuple[float, dict[tuple[int, int, int], list[Radio]], list[Radio], float] | None = None
        self._snap_reach = 0.0
        self._dirty = True
        self._pairs: dict[tuple[Radio, Radio], _Neighbour] = {}  # paths asked for their delay alone
        self.lazy = True
        """Quiet pairs (``air.py``): a static pair whose receiver does not judge the frame gets no arrival,
        its interference is gathered when the receiver needs it.  False hands every arrival at once, as
        before issue 31 (the tests' oracle: the same traces, byte for byte)."""
        self.quiet_min = QUIET_MIN
        """A sender's pairs are quiet only when it has at least this many (tests lower it)."""
        self.air = Air()
        self._quiet: Quiet | None = None
        self._quiet_count: dict[Radio, int] = {}  # per sender: its quiet receivers
        self.tap: Any = None
        """Called ``tap(sender, frame, t, duration)`` for every transmission from a radio that listens
        here (one this host serves): how other hosts' media hear it (hilgate.daemon.network)."""

    def attach(self, radio: "Radio") -> None:
        for name in (radio.tx_channel, radio.rx_channel):
            if name not in self.channels:
                raise ValueError(f"modem {radio.host.id}: no channel {name!r}")
        self.radios.append(radio)
        self._dirty = True

    def detach(self, radio: "Radio") -> None:
        self.radios.remove(radio)
        self._dirty = True

    def topology_changed(self) -> None:
        """Forget cached distances (a pose source, a channel or a radio's parameters changed)."""
        self._dirty = True

    @property
    def modems(self) -> list[Any]:
        """The modems (hosts of the attached radios), in the order they were attached."""
        return [radio.host for radio in self.radios]

    def modem_by_address(self, channel: str, address: int) -> Any:
        """The modem listening on ``channel`` with ``address``, or None."""
        for radio in self.radios:
            if radio.rx_channel == channel and radio.address == address:
                return radio.host
        return None

    def _rebuild(self) -> None:
        """Neighbour lists per sender, in attachment order (``neighbours.py``).  A static pair out of range
        is left out of the lists altogether, so a transmission never visits it; a frame addressed to such
        a radio still gets its ``range`` error (:meth:`_beyond`)."""
        radios = self.radios
        quiet = self._quiet = quiet_index(radios, self.channels) if self.lazy else None
        if quiet is not None:
            for radio in radios:  # every radio: one may still hear an earlier topology's quiet records
                radio.air = self.air
        index = Neighbours(radios, self.channels, quiet, self.quiet_min)
        self._order = index.order
        self._neighbours = index.lists
        self._quiet_count = index.quiet_count
        self._unreachable = {}
        self._by_address = index.by_address
        self._roam = index.roam
        self._snap = None
        self._snap_reach = index.snap_reach
        self._pairs = {}
        self._dirty = False

    def _beyond(self, sender: "Radio", dst: int) -> tuple["Radio", ...]:
        """The radios with address ``dst`` on ``sender``'s channel that a static pair keeps out of its
        range (or without a position): they are in no neighbour list, and a frame addressed to them
        gets its ``range`` error here.  Cached per sender and address until the topology changes."""
        listed = {nb.radio for nb in self._neighbours[sender]}
        roaming = self._roam.get(sender)
        quiet = self._quiet
        found = tuple(
            radio for radio in self._by_address.get(dst, ())
            if radio is not sender and radio.rx_channel == sender.tx_channel
            and radio.listens and radio not in listed and sender.pose.static and radio.pose.static
            and (roaming is None or not roaming.covers(radio))
            and (quiet is None or quiet.tau(sender, radio) is None)
        )
        self._unreachable.setdefault(sender, {})[dst] = found
        return found

    def _moving_grid(self, t: float) -> tuple[float, dict[tuple[int, int, int], list["Radio"]], list["Radio"], float]:
        """Where every radio with a top speed was at ``t0`` (at most ``_snap_reach / 4`` metres ago at
        the fastest speed): (t0, grid with cells of 1.25 × the widest indexed range, radios without a
        position, that speed).  A radio within range ``r`` of a sender at ``t`` was within
        ``r + speed·|t − t0|`` ≤ one cell side of it at ``t0``, so the 27 cells around the sender hold it."""
        snap = self._snap
        if snap is not None and abs(t - snap[0]) * snap[3] <= 0.25 * self._snap_reach:
            return snap
        size = _cell_size(1.25 * self._snap_reach)
        grid: dict[tuple[int, int, int], list[Radio]] = {}
        nowhere: list[Radio] = []
        speed = 0.0
        for radio in self.radios:
            top = radio.pose.max_speed_mps
            if not math.isfinite(top):
                continue
            speed = max(speed, top)
            position = radio.pose.position(t)
            if position is None:
                nowhere.append(radio)
            else:
                grid.setdefault(_cell(position, size), []).append(radio)
        snap = self._snap = (t, grid, nowhere, speed)
        return snap

    def _visit(self, roaming: "_Roaming", here: tuple[float, ...], t: float, frame: "Frame") -> list[_Neighbour]:
        """The neighbours a transmission from ``here`` at ``t`` must look at, in attachment order: the
        listed ones (static pairs in range, radios without a top speed) and those the moving grid puts
        near.  A frame addressed to one the grid leaves out gets its ``range`` error here."""
        _, grid, nowhere, _ = self._moving_grid(t)
        visit = list(self._neighbours[roaming.sender])
        covers, entry = roaming.covers, roaming.entry
        for radio in _near(grid, here, _cell_size(1.25 * self._snap_reach)):
            if covers(radio):
                visit.append(entry(radio))
        for radio in nowhere:
            if covers(radio):
                visit.append(entry(radio))
        order = self._order
        visit.sort(key=lambda nb: order[nb.radio])
        dst = frame.dst_addr
        if dst != BROADCAST:
            addressed = [radio for radio in roaming.pool if radio.address == dst and covers(radio)] \
                if dst not in roaming.addresses else roaming.addresses[dst]
            roaming.addresses[dst] = addressed
            if addressed:
                seen = {nb.radio for nb in visit}
                for radio in addressed:
                    if radio not in seen:
                        radio.unreachable(frame)
        return visit

    def _all(self, roaming: "_Roaming") -> list[_Neighbour]:
        """Every neighbour of a sender the moving grid serves, in attachment order (when it has no
        position: then nobody hears it, and a frame addressed to one of them gets its range error)."""
        listed = self._neighbours[roaming.sender] + [roaming.entry(r) for r in roaming.pool if roaming.covers(r)]
        order = self._order
        listed.sort(key=lambda nb: order[nb.radio])
        return listed

    def propagation_delay(self, sender: "Radio", receiver: "Radio", t: float, in_range: bool = True) -> float | None:
        """τ from radio ``sender`` to radio ``receiver`` at ``t``, exactly what an arrival between them
        at ``t`` takes (the pair's own path: ``_Neighbour.delay_between``); None without a pose, or
        (``in_range``) out of the sender's range."""
        a, b = sender.pose.position(t), receiver.pose.position(t)
        if a is None or b is None:
            return None
        d = math.dist(a, b)
        rmin, rmax = sender.range_m
        if in_range and not rmin <= d <= rmax:
            return None
        return self._pair(sender, receiver).delay_between(d, a, b)

    def _pair(self, sender: "Radio", receiver: "Radio") -> _Neighbour:
        """The path from ``sender`` to ``receiver`` as transmissions see it (made once, kept until the
        topology changes)."""
        if self._dirty:
            self._rebuild()
        pair = self._pairs.get((sender, receiver))
        if pair is None:
            pair = self._pairs[(sender, receiver)] = _Neighbour(sender, receiver, self.channels[sender.tx_channel])
        return pair

    def transmit(self, sender: "Radio", frame: "Frame", t: float, duration: float) -> None:
        """``frame`` goes on air from ``sender`` at ``t`` for ``duration`` seconds: hand out its arrivals.

        (The frame's hot path: the common case, a static pair in range, calls nothing but the receiver's
        ``arrive``; what is rarer — moving pairs, quiet receivers, refusals — is in methods of its own.)"""
        if self._dirty:
            self._rebuild()
        if self.tap is not None and sender.listens:
            self.tap(sender, frame, t, duration)
        neighbours = self._neighbours[sender]
        dst = frame.dst_addr
        if self._roam:
            neighbours = self._roaming_neighbours(sender, frame, t, neighbours)
        if dst != BROADCAST:
            known = self._unreachable.get(sender)
            beyond = known.get(dst) if known is not None else None
            if beyond is None:
                beyond = self._beyond(sender, dst)
            for radio in beyond:  # addressed to a static radio out of range (never visited below)
                radio.unreachable(frame)
        air = self.air  # (inline: a sparse scene's frame pays no call for the air)
        air.seq += 1
        if duration > air.longest:
            air.longest = duration
        if air.records:
            air.prune(t)
        quiet_count = self._quiet_count.get(sender, 0) if self._quiet_count else 0
        if quiet_count:  # its quiet receivers hear it through the air record; those that judge it get
            # their arrival below, in attachment order with the others
            neighbours, quiet_count = self._with_judging(sender, t, duration, dst, neighbours, quiet_count)
        sender_position = None
        missed = 0  # neighbours the frame does not reach (counted this way round: they are the few)
        for nb in neighbours:
            loss: Any = nb
            if nb.static:  # in range (a listed static pair is): the common case, or a refusing receiver
                d = nb.d
                start = t + nb.tau
            else:
                if sender_position is None:
                    sender_position = sender.pose.position(t)
                    if sender_position is None:  # a vehicle without a pose is heard by nobody
                        missed += _heard_by_nobody(neighbours[neighbours.index(nb):], frame, dst)
                        break
                path = _moving_path(nb, sender_position, t, frame, dst)
                if path is None:
                    missed += 1
                    continue
                d, start, loss = path
            if nb.refused is not None:
                missed += _refused(nb, frame, t, start, duration, d, loss, dst)
                continue
            nb.radio.arrive(frame, t, start, start + duration, d, loss)
        self.arrivals += len(neighbours) - missed + quiet_count

    def _roaming_neighbours(self, sender: "Radio", frame: "Frame", t: float,
                            neighbours: list[_Neighbour]) -> list[_Neighbour]:
        """The neighbours of a sender the moving grid serves, at ``t`` (its listed ones otherwise)."""
        roaming = self._roam.get(sender)
        if roaming is None:
            return neighbours
        here = sender.pose.position(t)
        return self._visit(roaming, here, t, frame) if here is not None else self._all(roaming)

    def _with_judging(self, sender: "Radio", t: float, duration: float, dst: int, neighbours: list[_Neighbour],
                      quiet_count: int) -> tuple[list[_Neighbour], int]:
        """A quiet sender's transmission recorded on the air; its quiet receivers that judge the frame
        (its addressee, or every one for a broadcast) added to the neighbours, in attachment order, and
        no longer counted as quiet."""
        quiet = self._quiet
        self.air.record(sender, t, duration, dst, quiet)  # type: ignore[arg-type]
        if dst == BROADCAST:
            judging = [r for r in quiet.receivers if quiet.tau(sender, r) is not None]  # type: ignore[union-attr]
        else:
            judging = [r for r in self._by_address.get(dst, ()) if quiet.tau(sender, r) is not None]  # type: ignore[union-attr]
        if not judging:
            return neighbours, quiet_count
        extra = [quiet.pair(sender, r) for r in judging]  # type: ignore[union-attr]
        if neighbours:
            order = self._order
            return sorted(neighbours + extra, key=lambda nb: order[nb.radio]), quiet_count - len(judging)
        return extra, quiet_count - len(judging)


def _heard_by_nobody(rest: list[_Neighbour], frame: "Frame", dst: int) -> int:
    """The sender has no pose: every radio that would have judged the frame is told why it could not
    (``no_pose``); all of ``rest`` are missed."""
    for other in rest:
        if dst == BROADCAST or other.radio.address == dst:
            other.radio.unreachable(frame, NO_POSE)
    return len(rest)


def _moving_path(nb: _Neighbour, here: "tuple[float, ...]", t: float, frame: "Frame",
                 dst: int) -> tuple[float, float, Any] | None:
    """A moving pair at ``t`` with the sender at ``here``: (distance, the arrival's start, its loss
    model), or None when the frame cannot reach the receiver (no pose, out of range: said to the
    radio that would have judged it)."""
    radio = nb.radio
    there = radio.pose.position(t)
    if there is None:
        if dst == BROADCAST or radio.address == dst:  # it cannot be judged: said, with why
            radio.unreachable(frame, NO_POSE)
        return None
    d = math.dist(here, there)
    if d < nb.rmin or d > nb.rmax:
        if radio.address == dst:
            radio.unreachable(frame)
        return None
    if nb.positional:  # the water between these two positions, looked up once for this arrival
        loss, tau = nb.water_between(here, there)
        return d, t + tau, loss
    return d, t + nb.delay(d, here, there), nb


def _refused(nb: _Neighbour, frame: "Frame", t: float, start: float, duration: float, d: float, loss: Any,
             dst: int) -> int:
    """A receiver that refuses the sender: outside its band it hears nothing (1: missed); a modulation
    it does not decode is interference only (0)."""
    radio = nb.radio
    if not nb.interferes:
        if radio.address == dst:
            radio.unreachable(frame, nb.refused)
        return 1
    radio.arrive_refused(frame, t, start, start + duration, d, loss, nb.refused)
    return 0
