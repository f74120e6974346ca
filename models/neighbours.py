"""The medium's neighbour index: for each sender, the pairs a transmission visits, and what is kept about them.

:class:`Neighbours` is built from the radios and channels each time the topology changes
(``Medium._rebuild``); the medium reads its lists on every transmission.  Kept apart from the medium
(``medium.py``: who hears whom, when, and with which loss) because it is a cache with rules of its own:

- a **pair** (:class:`_Neighbour`) keeps what can be precomputed for a sender and a receiver: a static
  pair's distance, delay and loss model, bound once;
- a static sender with a finite range only looks at the static radios in the grid cells around it (cells
  as wide as its range: :func:`_static_grid`), so building the lists is O(n · neighbours), not O(n²); a
  static pair out of range is never listed;
- a sender with many moving neighbours finds them through a grid of where they were a moment ago
  (:class:`_Roaming`; the medium's ``_moving_grid``);
- a dense scene's static pairs that judge nothing are **quiet** (``air.py``): counted, not listed, when
  the channel's propagation depends on distance alone (``Propagation.distance_only``).

Every list keeps the radios' attachment order (the order arrivals are handed out, which fixes the order
of same-instant events), so traces are the same as with a full scan.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from .air import Quiet

if TYPE_CHECKING:
    from .medium import Channel
    from .radio import Radio
    from .trajectories import Vec3

__all__ = ["Neighbours", "QUIET_MIN", "ROAMING_MIN"]


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


class Neighbours:
    """The neighbour lists of one topology (see the module's docstring): ``lists`` per sender (static pairs
    in range, moving pairs, in attachment order), ``quiet`` and ``quiet_count`` (a sender's quiet
    receivers, counted), ``roam`` (the senders the moving grid serves), ``by_address``, ``order``."""

    def __init__(self, radios: list["Radio"], channels: dict[str, "Channel"], quiet: Quiet | None,
                 quiet_min: int):
        self.radios = radios
        self.channels = channels
        self.order = {radio: i for i, radio in enumerate(radios)}
        self.moving = [radio for radio in radios if not radio.pose.static]
        self.unbounded = [radio for radio in radios if not math.isfinite(radio.pose.max_speed_mps)]
        self.moving_unbounded = [radio for radio in self.unbounded if not radio.pose.static]
        self.pools, self.pooled_static = _pools(radios)
        self.grids: dict[float, dict[tuple[int, int, int], list[Radio]]] = {}
        self.quiet = quiet
        self.quiet_min = quiet_min
        self.lists: dict[Radio, list[_Neighbour]] = {}
        self.quiet_count: dict[Radio, int] = {}
        self.roam: dict[Radio, _Roaming] = {}
        for sender in radios:
            self._list(sender)
        self.by_address: dict[int, list[Radio]] = {}
        for radio in radios:
            self.by_address.setdefault(radio.address, []).append(radio)
        reach = [sender.range_m[1] for sender in self.roam]
        self.snap_reach = max(max(reach), 1.0) if reach else 0.0

    def _list(self, sender: "Radio") -> None:
        channel = self.channels[sender.tx_channel]
        roaming = self._roaming(sender, channel)
        candidates, count = self._quiet_split(sender, self._candidates(sender, roaming))
        listed = []
        for receiver in candidates:
            if receiver is sender or receiver.rx_channel != sender.tx_channel or not receiver.listens:
                continue
            if roaming is not None and roaming.covers(receiver):
                continue  # found through the moving grid at each transmission
            nb = _Neighbour(sender, receiver, channel)
            if not nb.static or nb.in_range:
                listed.append(nb)
        self.lists[sender] = listed
        if count:
            self.quiet_count[sender] = count
        if roaming is not None:
            self.roam[sender] = roaming

    def _roaming(self, sender: "Radio", channel: "Channel") -> "_Roaming | None":
        """The moving grid's part of ``sender``'s neighbours, if it has more than ``ROAMING_MIN`` of them."""
        if not math.isfinite(sender.range_m[1]):
            return None
        pool = self.pools.get(sender.tx_channel, set())
        roamers = len(pool) - (sender in pool)
        if sender.pose.static:  # its static pairs are listed once, not roaming
            roamers = len(pool) - self.pooled_static.get(sender.tx_channel, 0)
        if roamers <= ROAMING_MIN or not pool:
            return None
        return _Roaming(sender, channel, pool)

    def _candidates(self, sender: "Radio", roaming: "_Roaming | None") -> list["Radio"]:
        """Who to look at: the moving grid finds the moving radios with a top speed when it serves this
        sender (and every radio with a top speed when the sender itself moves); a static sender with a
        finite range looks at the static radios of the grid cells around it."""
        rmax = sender.range_m[1]
        if not (sender.pose.static and math.isfinite(rmax)):
            return self.unbounded if roaming is not None else self.radios
        others = self.moving_unbounded if roaming is not None else self.moving
        origin = sender.pose.position(0.0)
        if origin is None:
            return others
        grid = self.grids.get(rmax)
        if grid is None:
            grid = self.grids[rmax] = _static_grid(self.radios, rmax)
        candidates = _near(grid, origin, _cell_size(rmax))
        candidates.extend(others)
        candidates.sort(key=self.order.__getitem__)
        return candidates

    def _quiet_split(self, sender: "Radio", candidates: list["Radio"]) -> tuple[list["Radio"], int]:
        """A quiet sender's quiet receivers are counted, not listed (handed an arrival only when they
        judge); a sparse sender's few arrivals are cheaper handed at once."""
        quiet = self.quiet
        if quiet is None or sender not in quiet.senders:
            return candidates, 0
        count, rest = quiet.split(sender, candidates)
        if count >= self.quiet_min:
            return rest, count
        quiet.drop(sender)
        return candidates, 0


def _pools(radios: list["Radio"]) -> tuple[dict[str, set["Radio"]], dict[str, int]]:
    """Per channel: the listening radios with a top speed, and how many of them are static."""
    pools: dict[str, set[Radio]] = {}
    pooled_static: dict[str, int] = {}
    for radio in radios:
        if radio.listens and math.isfinite(radio.pose.max_speed_mps):
            pools.setdefault(radio.rx_channel, set()).add(radio)
            pooled_static[radio.rx_channel] = pooled_static.get(radio.rx_channel, 0) + bool(radio.pose.static)
    return pools, pooled_static


def quiet_index(radios: list["Radio"], channels: dict[str, "Channel"]) -> Quiet:
    """The quiet pairs' snapshot: static senders and receivers with a position on channels whose paths
    depend on distance alone (receivers that judge every frame are never quiet)."""
    quiet = Quiet(channels)
    for radio in radios:
        position = radio.pose.position(0.0) if radio.pose.static else None
        if position is None or not channels[radio.tx_channel].propagation.distance_only:
            continue
        quiet.add_sender(radio, position)
        if radio.listens and not radio.judges_all:
            quiet.add_receiver(radio, position)
    return quiet
