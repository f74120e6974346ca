"""Who hears whom, when, and whether it survives: channels, propagation, range, collisions, errors.

For one transmission the medium walks the sender's *neighbours* (every modem listening on the
sender's transmit channel) once.  An arrival that someone must judge (the addressed receiver, every
receiver of a broadcast, a promiscuous modem or a MAC that overhears) gets an :class:`Arrival`, an
overlap check against what the receiver hears, an error draw and one event at its end.  Any other
arrival is only interference: a ``(start, end)`` pair in the receiver's ``rx_noise`` that can spoil
the judged ones.  Expired entries are dropped as the lists are walked (``rx_noise`` once it holds
more than a few), so each list stays as short as the number of frames on air at once.  Distances between vehicles that never move are computed
once per pair; that is what keeps the hot path O(1) per arrival.

The arithmetic is DESIGN.md's "timing and loss model", steps 3 to 5.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable

from .frame import BROADCAST

OVERLAP_EPS = 1e-9
"""Arrivals must overlap by more than a nanosecond to collide: back-to-back frames computed along
different floating-point paths (t + τ + T versus (t + T) + τ) may otherwise "overlap" by one ulp."""

if TYPE_CHECKING:
    from .clock import Clock
    from .frame import Frame
    from .modem import SimModem


@dataclass(frozen=True)
class Channel:
    """A shared medium: propagation delay τ = ``min_delay_s`` + d / ``speed_mps``."""

    name: str
    speed_mps: float
    min_delay_s: float = 0.0

    def delay(self, d: float) -> float:
        return self.min_delay_s + d / self.speed_mps


class Arrival:
    """One frame reaching one receiver over ``[start, end]``; flags set as the medium learns more."""

    __slots__ = ("frame", "start", "end", "d", "error", "collided")

    def __init__(self, frame: "Frame", start: float, end: float, d: float):
        self.frame = frame
        self.start = start
        self.end = end
        self.d = d
        self.error = False
        self.collided = False

    def __repr__(self) -> str:
        return f"Arrival({self.frame!r} [{self.start:.6f}, {self.end:.6f}] d={self.d:.3f})"


class _Neighbour:
    """A (sender, receiver) pair on the sender's transmit channel, with what can be precomputed."""

    __slots__ = ("receiver", "static", "d", "tau", "in_range", "rmin", "rmax", "min_delay", "speed", "per_cache")

    def __init__(self, sender: "SimModem", receiver: "SimModem", channel: Channel):
        self.receiver = receiver
        self.rmin, self.rmax = sender.range_m
        self.min_delay = channel.min_delay_s
        self.speed = channel.speed_mps
        self.per_cache: dict[int, float] = {}
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


class Medium:
    """All channels of a scene and every simulated modem attached to them."""

    def __init__(self, clock: "Clock", channels: Iterable[Channel]):
        self.clock = clock
        self.channels = {c.name: c for c in channels}
        self.modems: list[SimModem] = []
        self.frame_ids = itertools.count(1)
        self.arrivals = 0
        self._dirty = True

    def new_frame_id(self) -> int:
        return next(self.frame_ids)

    def attach(self, modem: "SimModem") -> None:
        for name in (modem.tx_channel, modem.rx_channel):
            if name not in self.channels:
                raise ValueError(f"modem {modem.id}: no channel {name!r}")
        self.modems.append(modem)
        self._dirty = True

    def detach(self, modem: "SimModem") -> None:
        self.modems.remove(modem)
        self._dirty = True

    def topology_changed(self) -> None:
        """Forget cached distances (a pose source or a modem's range changed)."""
        self._dirty = True

    def modem_by_address(self, channel: str, address: int) -> "SimModem | None":
        for modem in self.modems:
            if modem.rx_channel == channel and modem.address == address:
                return modem
        return None

    def _rebuild(self) -> None:
        for sender in self.modems:
            channel = self.channels[sender.tx_channel]
            sender.neighbours = [
                _Neighbour(sender, receiver, channel)
                for receiver in self.modems
                if receiver is not sender and receiver.rx_channel == sender.tx_channel
            ]
        self._dirty = False

    def propagation_delay(self, sender: "SimModem", receiver: "SimModem", t: float) -> float | None:
        """τ from ``sender`` to ``receiver`` at ``t``, or None if out of range or without a pose."""
        a, b = sender.pose.position(t), receiver.pose.position(t)
        if a is None or b is None:
            return None
        d = math.dist(a, b)
        rmin, rmax = sender.range_m
        if not rmin <= d <= rmax:
            return None
        return self.channels[sender.tx_channel].delay(d)

    def transmit(self, sender: "SimModem", frame: "Frame", t: float, duration: float) -> None:
        """``frame`` goes on air at ``t`` for ``duration`` seconds: create its arrivals."""
        if self._dirty:
            self._rebuild()
        dst = frame.dst_addr
        size = frame.size
        at = self.clock.at
        sender_position = None
        count = 0
        for nb in sender.neighbours:
            receiver = nb.receiver
            if nb.static:
                if not nb.in_range:
                    if receiver.address == dst:
                        receiver.unreachable(frame)
                    continue
                d = nb.d
                start = t + nb.tau
            else:
                if sender_position is None:
                    sender_position = sender.pose.position(t)
                    if sender_position is None:  # a vehicle without a pose is heard by nobody
                        if dst != BROADCAST:
                            target = next((n.receiver for n in sender.neighbours if n.receiver.address == dst), None)
                            if target is not None:
                                target.unreachable(frame)
                        break
                receiver_position = receiver.pose.position(t)
                if receiver_position is None:
                    if receiver.address == dst:
                        receiver.unreachable(frame)
                    continue
                d = math.dist(sender_position, receiver_position)
                if d < nb.rmin or d > nb.rmax:
                    if receiver.address == dst:
                        receiver.unreachable(frame)
                    continue
                start = t + nb.min_delay + d / nb.speed
            end = start + duration
            count += 1
            if receiver.hears_all or dst == receiver.address or dst == BROADCAST:
                # An arrival someone must judge: full bookkeeping, an error draw, an event at its end.
                arrival = Arrival(frame, start, end, d)
                live = []
                for other in receiver.rx_pending:
                    if other.end > t:
                        live.append(other)
                        if other.start < end - OVERLAP_EPS and start < other.end - OVERLAP_EPS:
                            other.collided = True
                            arrival.collided = True
                live.append(arrival)
                receiver.rx_pending = live
                if not arrival.collided:
                    for other_start, other_end in receiver.rx_noise:
                        if other_start < end - OVERLAP_EPS and start < other_end - OVERLAP_EPS:
                            arrival.collided = True
                            break
                    if (receiver.half_duplex and receiver.tx_end - OVERLAP_EPS > start
                            and receiver.tx_start < end - OVERLAP_EPS):
                        arrival.collided = True
                if not receiver.error_free:
                    if nb.static:
                        per = nb.per_cache.get(size)
                        if per is None:
                            per = nb.per_cache[size] = receiver.error.per(d, size)
                    else:
                        per = receiver.error.per(d, size)
                    if per > 0.0 and (per >= 1.0 or receiver.rng.random() < per):
                        arrival.error = True
                at(end, receiver.arrival_end, arrival)
            else:
                # Only interference: it can spoil arrivals at this receiver but has no outcome itself.
                for other in receiver.rx_pending:
                    if other.start < end - OVERLAP_EPS and start < other.end - OVERLAP_EPS:
                        other.collided = True
                noise = receiver.rx_noise
                noise.append((start, end))
                if len(noise) > 8:
                    receiver.rx_noise = [span for span in noise if span[1] > t]
        self.arrivals += count
