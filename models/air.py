"""Interference gathered lazily: what is in the air on each channel, and which radios hear it quietly.

In a dense scene (every modem hears every other) most arrivals are judged by nobody: a frame to one
modem reaches a thousand others only as interference.  Handing each of them an arrival at once costs
the medium O(N) per transmission, and keeping each static pair's path costs O(N²) memory.  Instead a
static pair whose receiver does not judge the frame is **quiet**: the medium records the transmission
once per channel (:class:`Air`) and the receiver asks for what overlapped only when it needs it, when
it judges an arrival (at its end) or senses the carrier.  The answer is the one the eager hand-out
gave, bit for bit: the same arrival interval (``t + τ``, ``+ duration``, τ and the range from the same
positions), the same overlap test, and under ``collisions: sinr`` the same powers summed in the same
order (the order of transmissions).

A pair is quiet when the sender has many (``medium.QUIET_MIN``: a sparse sender's few arrivals cost
less handed at once than the records every judgment on the channel scans), both ends are static with a
position, the receiver listens on the sender's
channel (a straight-line one: a ray-traced channel keeps its per-arrival lookups), does not judge every
frame (promiscuous modems and overhearing MACs are handed everything), is within the sender's range,
and does not refuse the sender (band, modulation).  Which pairs are quiet is decided on a snapshot of
the radios taken when the medium rebuilds its lists (:class:`Quiet`); each record keeps the snapshot it
was sent under, so a later change of topology does not change what an earlier transmission was.

Records are dropped once no arrival still to be judged can overlap them: an arrival is judged at its
end, at most the longest duration sent after it starts, so a record whose every arrival ended longer
ago than that is dead.  Each record is appended and dropped once: O(1) amortised per transmission; a judgment costs
the number of transmissions in the air.
"""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING, Any, Iterator

from .frame import BROADCAST
from .path import front_of

if TYPE_CHECKING:
    from .medium import Channel
    from .neighbours import _Neighbour
    from .radio import Radio

_UNKNOWN = object()


class Quiet:
    """The quiet pairs of one topology, decided on a snapshot of the radios taken when it was built.

    Nothing per pair is kept until a receiver asks: τ of a pair is worked out at its first question and
    remembered per receiver (only receivers that judge or sense ask), the pair's path (its loss model,
    for a judged arrival or a received power) made on first use."""

    __slots__ = ("senders", "receivers", "refusals", "taus", "pairs", "reach", "channels")

    def __init__(self, channels: dict[str, "Channel"]):
        self.channels = channels
        self.senders: dict[Radio, tuple[Any, float, float, str, Any]] = {}  # position, rmin, rmax, channel, front
        self.receivers: dict[Radio, tuple[Any, int, str, Any]] = {}  # position, address, channel, front
        self.refusals: dict[tuple[int, int], bool] = {}  # by (id of the sender's front, id of the receiver's)
        self.taus: dict[Radio, dict[Radio, float | None]] = {}  # receiver → sender → τ (None: not quiet)
        self.pairs: dict[tuple[Radio, Radio], _Neighbour] = {}
        self.reach: dict[str, float] = {}  # per channel: the largest τ of a quiet pair

    def add_sender(self, radio: "Radio", position: Any) -> None:
        self.senders[radio] = (position, radio.range_m[0], radio.range_m[1], radio.tx_channel, front_of(radio))

    def add_receiver(self, radio: "Radio", position: Any) -> None:
        self.receivers[radio] = (position, radio.address, radio.rx_channel, front_of(radio))

    def delay(self, sender: "Radio", receiver: "Radio") -> float | None:
        """τ of the pair if it is quiet, else None (worked out here, not remembered: the medium asks
        every pair once when it counts them)."""
        s = self.senders.get(sender)
        r = self.receivers.get(receiver)
        if s is None or r is None or sender is receiver or s[3] != r[2]:
            return None
        a, b = s[0], r[0]
        d = math.dist(a, b)
        if not s[1] <= d <= s[2]:
            return None
        tx, rx = s[4], r[3]
        if tx is not None and rx is not None and self._refuses(tx, rx):
            return None
        tau = self.channels[s[3]].propagation.delay(d, a, b)  # as _Neighbour works it out
        if tau > self.reach.get(s[3], -1.0):
            self.reach[s[3]] = tau
        return tau

    def split(self, sender: "Radio", candidates: list["Radio"]) -> tuple[int, list["Radio"]]:
        """When the medium lists a quiet sender's neighbours: how many of ``candidates`` are quiet, and
        those that are not and must still be looked at (the sender's static pairs out of range are
        neither: they are never listed).  The same decisions as :meth:`delay`, in one loop: this is
        the O(n²) of a dense scene's listing."""
        a, rmin, rmax, channel, tx = self.senders[sender]
        receivers = self.receivers
        dist = math.dist
        rest = []
        count = 0
        far = -1.0
        for receiver in candidates:
            r = receivers.get(receiver)
            if r is None or r[2] != channel or receiver is sender:
                rest.append(receiver)
                continue
            d = dist(a, r[0])
            if not rmin <= d <= rmax:
                continue
            rx = r[3]
            if tx is not None and rx is not None and self._refuses(tx, rx):
                rest.append(receiver)
                continue
            count += 1
            if d > far:
                far = d
        if far >= 0.0:  # a straight line's τ grows with d: the farthest quiet pair has the largest
            tau = self.channels[channel].propagation.delay(far)
            if tau > self.reach.get(channel, -1.0):
                self.reach[channel] = tau
        return count, rest

    def drop(self, sender: "Radio") -> None:
        """``sender``'s pairs are not quiet after all (too few: the medium lists them)."""
        del self.senders[sender]

    def _refuses(self, tx: Any, rx: Any) -> bool:
        key = (id(tx), id(rx))
        refused = self.refusals.get(key)
        if refused is None:
            refused = self.refusals[key] = rx.refuses(tx) is not None
        return refused

    def tau(self, sender: "Radio", receiver: "Radio") -> float | None:
        """τ of a quiet pair, remembered for this receiver; None if the pair is not quiet."""
        known = self.taus.get(receiver)
        if known is None:
            known = self.taus[receiver] = {}
        tau = known.get(sender, _UNKNOWN)
        if tau is _UNKNOWN:
            tau = known[sender] = self.delay(sender, receiver)
        return tau  # type: ignore[return-value]

    def pair(self, sender: "Radio", receiver: "Radio") -> "_Neighbour":
        """The path of a quiet pair, made on first use."""
        from .neighbours import _Neighbour

        nb = self.pairs.get((sender, receiver))
        if nb is None:
            nb = self.pairs[(sender, receiver)] = _Neighbour(sender, receiver, self.channels[sender.tx_channel])
        return nb


class _Record:
    """One transmission with quiet receivers, under the topology it was sent in (``quiet``)."""

    __slots__ = ("seq", "t", "duration", "dst", "sender", "quiet", "last")

    def __init__(self, seq: int, t: float, duration: float, dst: int, sender: "Radio", quiet: Quiet, last: float):
        self.seq = seq
        self.t = t
        self.duration = duration
        self.dst = dst
        self.sender = sender
        self.quiet = quiet
        self.last = last  # no quiet arrival of it ends later


class Air:
    """The transmissions in the air that have quiet receivers, per channel, in the order they were sent.

    The medium keeps ``seq`` (every transmission's number: the order in which an arrival's interference
    is summed under ``collisions: sinr``) and ``longest`` (the longest duration sent) itself, without a
    call: a sparse scene, which never records anything, pays nothing else for the air."""

    __slots__ = ("records", "longest", "seq")

    def __init__(self) -> None:
        self.records: dict[str, deque[_Record]] = {}  # only channels with records
        self.longest = 0.0
        self.seq = 0

    def prune(self, t: float) -> None:
        """A transmission at ``t``: drop the records no arrival still to be judged can overlap, on every
        channel (one that fell quiet too).  An arrival is judged at its end, at most ``longest`` after it
        starts; a transmission heard late from another host (real time only) is judged against what is
        still recorded, as the eager hand-out judged it against what its lists still held."""
        horizon = t - self.longest
        for channel, records in list(self.records.items()):
            while records and records[0].last < horizon:
                records.popleft()
            if not records:
                del self.records[channel]

    def record(self, sender: "Radio", t: float, duration: float, dst: int, quiet: Quiet) -> None:
        """A transmission of ``sender`` that has quiet receivers.  A broadcast has none (every receiver
        judges it) and is not kept."""
        if dst == BROADCAST:
            return
        channel = sender.tx_channel
        records = self.records.get(channel)
        if records is None:
            records = self.records[channel] = deque()
        last = (t + quiet.reach.get(channel, 0.0)) + duration  # as late as an arrival of it can end
        records.append(_Record(self.seq, t, duration, dst, sender, quiet, last))

    def _heard(self, radio: "Radio") -> Iterator[tuple[_Record, float]]:
        """The quiet arrivals at ``radio`` in the air: (record, start)."""
        for records in self.records.values():
            for rec in records:
                quiet = rec.quiet
                known = quiet.receivers.get(radio)
                if known is None or rec.dst == known[1]:  # not a quiet receiver then, or it judged the frame
                    continue
                tau = quiet.tau(rec.sender, radio)
                if tau is not None:
                    yield rec, rec.t + tau

    def overlaps(self, radio: "Radio", start: float, end: float, eps: float) -> bool:
        """A quiet arrival at ``radio`` overlaps ``[start, end]`` (by more than ``eps``)."""
        if not self.records:  # (no quiet sender yet: a sparse scene never has one)
            return False
        for rec, other_start in self._heard(radio):
            if other_start < end - eps and start < other_start + rec.duration - eps:
                return True
        return False

    def busy(self, radio: "Radio", now: float) -> bool:
        """A quiet arrival at ``radio`` is on air at ``now``."""
        if not self.records:
            return False
        for rec, other_start in self._heard(radio):
            if other_start <= now < other_start + rec.duration:
                return True
        return False

    def powers(self, radio: "Radio", start: float, end: float, eps: float) -> list[tuple[int, float]]:
        """(seq, received power) of the quiet arrivals at ``radio`` overlapping ``[start, end]``."""
        found: list[tuple[int, float]] = []
        if not self.records:
            return found
        for rec, other_start in self._heard(radio):
            if other_start < end - eps and start < other_start + rec.duration - eps:
                nb = rec.quiet.pair(rec.sender, radio)
                found.append((rec.seq, nb.rx_power(nb.d)))
        return found
