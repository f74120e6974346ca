"""Who hears whom, when, and how likely it survives: channels, propagation, range, error model.

For one transmission the medium walks the sending radio's *neighbours* (every radio listening on
the sender's transmit channel) once.  For each it works out, through the channel, whether the frame
reaches it and over which interval, and hands it the arrival in one call (:meth:`Radio.arrive`,
with the path's loss probability from the error model); the receiving radio keeps what it hears and
decides collisions (``radio.py``).  Distances between vehicles that never move, and the loss
probability on such a path, are computed once per pair; that is what keeps the hot path O(1) per
arrival.

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
from .propagation import Propagation
from .propagations import PROPAGATIONS, implied

NO_POSE = "no_pose"
"""The cause of a frame that cannot be judged because the sender or a receiver has no position (a live
vehicle before its first pose, a stale one dropped): traced at each radio that would have judged it."""

if TYPE_CHECKING:
    from .clock import Clock
    from .frame import Frame
    from .radio import Radio
    from .trajectories import Vec3


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


class _Neighbour:
    """A (sender, receiver) pair on the sender's transmit channel, with what can be precomputed.

    It is also the loss model handed with each arrival on this path: the receiver's error model bound
    to the sender (``path.py``) at the distance, cached per frame size when neither vehicle moves.  A
    pair whose receiver refuses the sender (``refused``: another band, a modulation it does not decode)
    never takes the fast path (``reach`` is False).  On a channel whose propagation is ``positional`` (the
    water's BELLHOP fields) the bound model is looked up at both ends' positions: once for a static pair,
    at every arrival for a moving one."""

    __slots__ = ("radio", "static", "reach", "d", "tau", "in_range", "rmin", "rmax", "delay", "min_delay",
                 "per_cache", "model", "power", "refused", "interferes", "positional")

    def __init__(self, sender: "Radio", receiver: "Radio", channel: Channel):
        self.radio = receiver
        self.rmin, self.rmax = sender.range_m
        propagation = channel.propagation
        self.delay = propagation.delay  # a moving pair asks it at every transmission
        self.per_cache: dict[int, float] | None = None  # made at the first loss drawn: a million pairs, few draw
        self.model, self.refused, self.interferes = propagation.bind(sender, receiver)
        self.positional = propagation.positional  # each arrival's delay and loss from both ends' positions
        self.min_delay = channel.min_delay_s
        self.power = -1.0  # received power on a static path, once asked (collisions: sinr)
        self.static = bool(sender.pose.static and receiver.pose.static)
        self.d = self.tau = 0.0
        self.in_range = False
        if self.static:
            a = sender.pose.position(0.0)
            b = receiver.pose.position(0.0)
            if a is None or b is None:
                self.in_range = False
            else:
                self.d = math.dist(a, b)
                if self.positional:  # a static pair looks the water up once
                    self.model, self.tau = self.water_between(a, b)
                    self.positional = False
                else:
                    self.tau = propagation.delay(self.d, a, b)
                self.in_range = self.rmin <= self.d <= self.rmax
        self.reach = self.static and self.in_range and self.refused is None  # the common case, tested first

    def water_between(self, a: "Vec3", b: "Vec3") -> tuple[Any, float]:
        """On a ``positional`` channel: this arrival's loss model at both ends' positions and its delay
        (the channel's ``min_delay_s`` added), from the fields of this pair's frequency."""
        loss = self.model.at(a, b)
        return loss, self.min_delay + loss.delay

    def delay_between(self, d: float, a: "Vec3", b: "Vec3") -> float:
        """τ of this path with its ends at ``a`` and ``b`` (``d`` apart): what an arrival on it takes,
        and what every other asker (an emulated modem's ``AT?T``, an acknowledgement, a late remote
        transmission) is told."""
        if self.static:
            return self.tau
        if self.positional:
            return self.water_between(a, b)[1]
        return self.delay(d, a, b)

    def per(self, d: float, size: int) -> float:
        """Probability that a frame of ``size`` bytes is lost on this path at distance ``d``."""
        if self.static:
            cache = self.per_cache
            if cache is None:
                cache = self.per_cache = {}
            per = cache.get(size)
            if per is None:
                per = cache[size] = self.model.per(d, size)
            return per
        return self.model.per(d, size)

    def rx_power(self, d: float) -> float:
        """Received power at ``d`` (physical models only: ``collisions: sinr``)."""
        if self.static:
            if self.power < 0.0:
                self.power = self.model.rx_power(d)
            return self.power
        return self.model.rx_power(d)

    def per_sinr(self, d: float, size: int, interference: float) -> float:
        """Loss probability with ``interference`` added to the noise (``collisions: sinr``)."""
        return self.model.per_sinr(d, size, interference)


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
        """Neighbour lists per sender, in attachment order (the order arrivals are handed out, which
        fixes the order of same-instant events).

        A static pair out of range is left out of the list altogether, so a transmission never visits
        it; a frame addressed to such a radio still gets its ``range`` error (:meth:`_beyond`).  A
        static sender with a finite range only looks at the static radios in the grid cells around it
        (cells as wide as its range: ``_static_grid``), so building the lists is O(n · neighbours),
        not O(n²)."""
        radios = self.radios
        order = self._order = {radio: i for i, radio in enumerate(radios)}
        moving = [radio for radio in radios if not radio.pose.static]
        unbounded = [radio for radio in radios if not math.isfinite(radio.pose.max_speed_mps)]
        moving_unbounded = [radio for radio in unbounded if not radio.pose.static]
        pools: dict[str, set[Radio]] = {}  # per channel: listening radios with a top speed
        pooled_static: dict[str, int] = {}  # and how many of them are static
        for radio in radios:
            if radio.listens and math.isfinite(radio.pose.max_speed_mps):
                pools.setdefault(radio.rx_channel, set()).add(radio)
                pooled_static[radio.rx_channel] = pooled_static.get(radio.rx_channel, 0) + bool(radio.pose.static)
        grids: dict[float, dict[tuple[int, int, int], list[Radio]]] = {}
        neighbours = {}
        quiet = self._quiet = Quiet(self.channels) if self.lazy else None
        quiet_count: dict[Radio, int] = {}
        if quiet is not None:
            for radio in radios:
                position = radio.pose.position(0.0) if radio.pose.static else None
                if position is None or not self.channels[radio.tx_channel].propagation.distance_only:
                    continue
                quiet.add_sender(radio, position)
                if radio.listens and not radio.judges_all:
                    quiet.add_receiver(radio, position)
            for radio in radios:  # every radio: one may still hear an earlier topology's quiet records
                radio.air = self.air
        roam: dict[Radio, _Roaming] = {}
        for sender in radios:
            channel = self.channels[sender.tx_channel]
            rmax = sender.range_m[1]
            pool: set[Radio] = set()
            if math.isfinite(rmax):
                pool = pools.get(sender.tx_channel, set())
                roamers = len(pool) - (sender in pool)
                if sender.pose.static:  # its static pairs are listed once, not roaming
                    roamers = len(pool) - pooled_static.get(sender.tx_channel, 0)
                if roamers <= ROAMING_MIN:
                    pool = set()
            roaming = _Roaming(sender, channel, pool) if pool else None
            # who to list: the moving grid finds the moving radios with a top speed when it serves
            # this sender (and every radio with a top speed when the sender itself moves)
            if sender.pose.static and math.isfinite(rmax):
                others = moving_unbounded if roaming is not None else moving
                origin = sender.pose.position(0.0)
                if origin is None:
                    candidates = others
                else:
                    grid = grids.get(rmax)
                    if grid is None:
                        grid = grids[rmax] = _static_grid(radios, rmax)
                    candidates = _near(grid, origin, _cell_size(rmax))
                    candidates.extend(others)
                    candidates.sort(key=order.__getitem__)
            else:
                candidates = unbounded if roaming is not None else radios
            listed = []
            count = 0
            if quiet is not None and sender in quiet.senders:  # its quiet receivers are counted, not listed:
                count, rest = quiet.split(sender, candidates)  # handed an arrival only when they judge
                if count >= self.quiet_min:
                    candidates = rest
                else:  # a sparse sender: its few arrivals are cheaper handed at once
                    quiet.drop(sender)
                    count = 0
            for receiver in candidates:
                if receiver is sender or receiver.rx_channel != sender.tx_channel or not receiver.listens:
                    continue
                if roaming is not None and roaming.covers(receiver):
                    continue  # found through the moving grid at each transmission
                nb = _Neighbour(sender, receiver, channel)
                if not nb.static or nb.in_range:
                    listed.append(nb)
            neighbours[sender] = listed
            if count:
                quiet_count[sender] = count
            if roaming is not None:
                roam[sender] = roaming
        self._neighbours = neighbours
        self._quiet_count = quiet_count
        self._unreachable = {}
        by_address: dict[int, list[Radio]] = {}
        for radio in radios:
            by_address.setdefault(radio.address, []).append(radio)
        self._by_address = by_address
        self._roam = roam
        self._snap = None
        reach = [sender.range_m[1] for sender in roam]
        self._snap_reach = max(max(reach), 1.0) if reach else 0.0
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
        """``frame`` goes on air from ``sender`` at ``t`` for ``duration`` seconds: hand out its arrivals."""
        if self._dirty:
            self._rebuild()
        if self.tap is not None and sender.listens:
            self.tap(sender, frame, t, duration)
        neighbours = self._neighbours[sender]
        dst = frame.dst_addr
        if self._roam:
            roaming = self._roam.get(sender)
            if roaming is not None:
                here = sender.pose.position(t)
                neighbours = self._visit(roaming, here, t, frame) if here is not None else self._all(roaming)
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
            quiet = self._quiet
            air.record(sender, t, duration, dst, quiet)  # type: ignore[arg-type]
            if dst == BROADCAST:
                judging = [r for r in quiet.receivers if quiet.tau(sender, r) is not None]  # type: ignore[union-attr]
            else:
                judging = [r for r in self._by_address.get(dst, ()) if quiet.tau(sender, r) is not None]  # type: ignore[union-attr]
            if judging:
                quiet_count -= len(judging)
                extra = [quiet.pair(sender, r) for r in judging]  # type: ignore[union-attr]
                if neighbours:
                    order = self._order
                    neighbours = sorted(neighbours + extra, key=lambda nb: order[nb.radio])
                else:
                    neighbours = extra
        sender_position = None
        missed = 0  # neighbours the frame does not reach (counted this way round: they are the few)
        for nb in neighbours:
            radio = nb.radio
            loss: Any = nb
            if nb.reach:
                d = nb.d
                start = t + nb.tau
            elif nb.static:  # a listed static pair is in range: this receiver refuses the sender
                d = nb.d
                start = t + nb.tau
            else:
                if sender_position is None:
                    sender_position = sender.pose.position(t)
                    if sender_position is None:  # a vehicle without a pose is heard by nobody: every
                        # radio that would have judged the frame is told why it could not (no_pose)
                        rest = neighbours[neighbours.index(nb):]
                        for other in rest:
                            if dst == BROADCAST or other.radio.address == dst:
                                other.radio.unreachable(frame, NO_POSE)
                        missed += len(rest)
                        break
                receiver_position = radio.pose.position(t)
                if receiver_position is None:
                    if dst == BROADCAST or radio.address == dst:  # it cannot be judged: said, with why
                        radio.unreachable(frame, NO_POSE)
                    missed += 1
                    continue
                d = math.dist(sender_position, receiver_position)
                if d < nb.rmin or d > nb.rmax:
                    if radio.address == dst:
                        radio.unreachable(frame)
                    missed += 1
                    continue
                if nb.positional:  # the water between these two positions, looked up once for this arrival
                    loss, tau = nb.water_between(sender_position, receiver_position)
                    start = t + tau
                else:
                    start = t + nb.delay(d, sender_position, receiver_position)
            if nb.refused is not None:
                if not nb.interferes:  # outside its band: it hears nothing
                    if radio.address == dst:
                        radio.unreachable(frame, nb.refused)
                    missed += 1
                    continue
                radio.arrive_refused(frame, t, start, start + duration, d, loss, nb.refused)
                continue
            radio.arrive(frame, t, start, start + duration, d, loss)
        self.arrivals += len(neighbours) - missed + quiet_count


def _cell_size(rmax: float) -> float:
    """A grid cell a little wider than ``rmax``: two points within ``rmax`` of each other are then in
    the same or adjacent cells, whatever the rounding of the division."""
    return max(rmax, 1.0) * (1.0 + 1e-9)


def _cell(position: tuple[float, ...], size: float) -> tuple[int, int, int]:
    x, y, z = position[0], position[1], position[2] if len(position) > 2 else 0.0
    return (math.floor(x / size), math.floor(y / size), math.floor(z / size))


def _static_grid(radios: list["Radio"], rmax: float) -> dict[tuple[int, int, int], list["Radio"]]:
    """The static radios that have a position, by grid cell of side ``_cell_size(rmax)``."""
    size = _cell_size(rmax)
    grid: dict[tuple[int, int, int], list[Radio]] = {}
    for radio in radios:
        if radio.pose.static:
            position = radio.pose.position(0.0)
            if position is not None:
                grid.setdefault(_cell(position, size), []).append(radio)
    return grid


def _near(grid: dict[tuple[int, int, int], list["Radio"]], origin: tuple[float, ...], size: float) -> list["Radio"]:
    """The radios in the 27 cells around ``origin``: a superset of those within one cell side."""
    cx, cy, cz = _cell(origin, size)
    found: list[Radio] = []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                cell = grid.get((cx + dx, cy + dy, cz + dz))
                if cell is not None:
                    found.extend(cell)
    return found


QUIET_MIN = 32
"""A sender with fewer quiet pairs than this hands them their arrivals at once: every judgment on the
channel scans the air's records while they live, which costs more than a few arrivals (a sparse ring of
a thousand modems, each hearing four, would pay for every frame in the air at each judgment)."""

ROAMING_MIN = 32
"""A sender with more moving-pair neighbours (with a top speed) than this finds them through the
moving grid; below it, computing every distance is cheaper than the grid."""


class _Roaming:
    """The neighbours of ``sender`` that the moving grid serves: the radios of ``pool`` (listening on
    its channel, with a top speed) other than itself, and for a static sender only the moving ones
    (its static pairs are listed once).  Their entries are made on first use."""

    __slots__ = ("sender", "channel", "pool", "static", "entries", "addresses")

    def __init__(self, sender: "Radio", channel: Channel, pool: set["Radio"]):
        self.sender = sender
        self.channel = channel
        self.pool = pool
        self.static = bool(sender.pose.static)
        self.entries: dict[Radio, _Neighbour] = {}
        self.addresses: dict[int, list[Radio]] = {}

    def covers(self, radio: "Radio") -> bool:
        return radio in self.pool and radio is not self.sender and not (self.static and radio.pose.static)

    def entry(self, radio: "Radio") -> _Neighbour:
        nb = self.entries.get(radio)
        if nb is None:
            nb = self.entries[radio] = _Neighbour(self.sender, radio, self.channel)
        return nb
