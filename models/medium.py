"""Who hears whom, when, and how likely it survives: channels, propagation, range, error model.

For one transmission the medium walks the sending radio's *neighbours* (every radio listening on
the sender's transmit channel) once.  For each it works out, through the channel, whether the frame
reaches it and over which interval, and hands it the arrival in one call (:meth:`Radio.arrive`,
with the path's loss probability from the error model); the receiving radio keeps what it hears and
decides collisions (``radio.py``).  Distances between vehicles that never move, and the loss
probability on such a path, are computed once per pair; that is what keeps the hot path O(1) per
arrival.

The arithmetic is DESIGN.md's "timing and loss model", step 3 (and the PER of step 5).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable

from .frame import BROADCAST
from .radio import OVERLAP_EPS, Arrival  # noqa: F401  (their home was here; kept importable)

if TYPE_CHECKING:
    from .clock import Clock
    from .frame import Frame
    from .radio import Radio


@dataclass(frozen=True)
class Channel:
    """A shared medium: propagation delay τ = ``min_delay_s`` + d / ``speed_mps``."""

    name: str
    speed_mps: float
    min_delay_s: float = 0.0

    def delay(self, d: float) -> float:
        return self.min_delay_s + d / self.speed_mps


class _Neighbour:
    """A (sender, receiver) pair on the sender's transmit channel, with what can be precomputed.

    It is also the loss model handed with each arrival on this path: the receiver's error model at
    the distance, cached per frame size when neither vehicle moves."""

    __slots__ = ("radio", "static", "reach", "d", "tau", "in_range", "rmin", "rmax", "min_delay", "speed",
                 "per_cache", "model", "power")

    def __init__(self, sender: "Radio", receiver: "Radio", channel: Channel):
        self.radio = receiver
        self.rmin, self.rmax = sender.range_m
        self.min_delay = channel.min_delay_s
        self.speed = channel.speed_mps
        self.per_cache: dict[int, float] = {}
        error = receiver.error
        path_from = getattr(error, "path_from", None)  # a physical model takes the sender's source level
        self.model = path_from(sender.error) if path_from is not None else error
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
                self.tau = channel.delay(self.d)
                self.in_range = self.rmin <= self.d <= self.rmax
        self.reach = self.static and self.in_range  # the common case, tested first: d and tau are known

    def per(self, d: float, size: int) -> float:
        """Probability that a frame of ``size`` bytes is lost on this path at distance ``d``."""
        if self.static:
            per = self.per_cache.get(size)
            if per is None:
                per = self.per_cache[size] = self.model.per(d, size)
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
        self._dirty = True
        self.tap: Any = None
        """Called ``tap(sender, frame, t, duration)`` for every transmission from a radio that listens
        here (one this host serves): how other hosts' media hear it (hilgate.daemon.network)."""

    def new_frame_id(self) -> int:
        return next(self.frame_ids)

    def attach(self, radio: "Radio") -> None:
        for name in (radio.tx_channel, radio.rx_channel):
            if name not in self.channels:
                raise ValueError(f"modem {getattr(radio.host, 'id', radio)}: no channel {name!r}")
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
        not O(n²); pairs with a moving vehicle are always listed and judged at each transmission."""
        radios = self.radios
        order = {radio: i for i, radio in enumerate(radios)}
        moving = [radio for radio in radios if not radio.pose.static]
        grids: dict[float, dict[tuple[int, int, int], list[Radio]]] = {}
        neighbours = {}
        for sender in radios:
            channel = self.channels[sender.tx_channel]
            rmax = sender.range_m[1]
            if sender.pose.static and math.isfinite(rmax):
                origin = sender.pose.position(0.0)
                if origin is None:
                    candidates = moving
                else:
                    grid = grids.get(rmax)
                    if grid is None:
                        grid = grids[rmax] = _static_grid(radios, rmax)
                    candidates = _near(grid, origin, rmax)
                    candidates.extend(moving)
                    candidates.sort(key=order.__getitem__)
            else:
                candidates = radios
            listed = []
            for receiver in candidates:
                if receiver is sender or receiver.rx_channel != sender.tx_channel or not receiver.listens:
                    continue
                nb = _Neighbour(sender, receiver, channel)
                if not nb.static or nb.in_range:
                    listed.append(nb)
            neighbours[sender] = listed
        self._neighbours = neighbours
        self._unreachable = {}
        self._dirty = False

    def _beyond(self, sender: "Radio", dst: int) -> tuple["Radio", ...]:
        """The radios with address ``dst`` on ``sender``'s channel that a static pair keeps out of its
        range (or without a position): they are in no neighbour list, and a frame addressed to them
        gets its ``range`` error here.  Cached per sender and address until the topology changes."""
        listed = {nb.radio for nb in self._neighbours[sender]}
        found = tuple(
            radio for radio in self.radios
            if radio.address == dst and radio is not sender and radio.rx_channel == sender.tx_channel
            and radio.listens and radio not in listed and sender.pose.static and radio.pose.static
        )
        self._unreachable.setdefault(sender, {})[dst] = found
        return found

    def propagation_delay(self, sender: Any, receiver: Any, t: float) -> float | None:
        """τ from ``sender`` to ``receiver`` (modems or radios) at ``t``, or None if out of range or
        without a pose."""
        a, b = sender.pose.position(t), receiver.pose.position(t)
        if a is None or b is None:
            return None
        d = math.dist(a, b)
        rmin, rmax = sender.range_m
        if not rmin <= d <= rmax:
            return None
        return self.channels[sender.tx_channel].delay(d)

    def transmit(self, sender: "Radio", frame: "Frame", t: float, duration: float) -> None:
        """``frame`` goes on air from ``sender`` at ``t`` for ``duration`` seconds: hand out its arrivals."""
        if self._dirty:
            self._rebuild()
        if self.tap is not None and sender.listens:
            self.tap(sender, frame, t, duration)
        neighbours = self._neighbours[sender]
        dst = frame.dst_addr
        if dst != BROADCAST:
            known = self._unreachable.get(sender)
            beyond = known.get(dst) if known is not None else None
            if beyond is None:
                beyond = self._beyond(sender, dst)
            for radio in beyond:  # addressed to a static radio out of range (never visited below)
                radio.unreachable(frame)
        sender_position = None
        missed = 0  # neighbours the frame does not reach (counted this way round: they are the few)
        for nb in neighbours:
            radio = nb.radio
            if nb.reach:
                d = nb.d
                start = t + nb.tau
            else:
                if sender_position is None:
                    sender_position = sender.pose.position(t)
                    if sender_position is None:  # a vehicle without a pose is heard by nobody
                        if dst != BROADCAST:
                            target = next((n.radio for n in neighbours if n.radio.address == dst), None)
                            if target is not None:
                                target.unreachable(frame)
                        missed += len(neighbours) - neighbours.index(nb)
                        break
                receiver_position = radio.pose.position(t)
                if receiver_position is None:
                    if radio.address == dst:
                        radio.unreachable(frame)
                    missed += 1
                    continue
                d = math.dist(sender_position, receiver_position)
                if d < nb.rmin or d > nb.rmax:
                    if radio.address == dst:
                        radio.unreachable(frame)
                    missed += 1
                    continue
                start = t + nb.min_delay + d / nb.speed
            radio.arrive(frame, t, start, start + duration, d, nb)
        self.arrivals += len(neighbours) - missed


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


def _near(grid: dict[tuple[int, int, int], list["Radio"]], origin: tuple[float, ...], rmax: float) -> list["Radio"]:
    """The static radios in the 27 cells around ``origin``: a superset of those within ``rmax``."""
    cx, cy, cz = _cell(origin, _cell_size(rmax))
    found: list[Radio] = []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                cell = grid.get((cx + dx, cy + dy, cz + dz))
                if cell is not None:
                    found.extend(cell)
    return found
