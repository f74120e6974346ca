"""What became of every frame one host sends to another host's links: the receivers' reports and the
sender's ledger, so that no frame is lost between hosts without a trace line that names it.

Zenoh's publications say nothing about who got them.  A host cut off or frozen loses what was on the
way to it until the lease declares it down, a daemon killed loses what it had heard but not yet
delivered, and neither side knew which frames those were: the receiver saw at most a gap in the
message numbers (none at all once the sender had been down meanwhile, or when it was a new daemon),
the sender nothing.  So the two sides settle every frame:

**The receiver reports** (:class:`Receipts`, one per sender session).  Every :data:`REPORT_S` each host
tells each sender, on ``<prefix>/ack/<host>/<sender>``, up to which message number every transmission
is settled here (heard and its arrivals here over, so that its outcome is in this host's trace; or
never heard) and which numbers were never heard.  The ranges are cumulative (the last
:data:`MAX_RANGES`), so a report lost on the way is made good by the next; a report is repeated while
nothing changes.  A daemon's first report of a session says it heard nothing before its first number
(it was not there); its last, as it stops, says which of the heard ones will never arrive here.

**The sender settles** (:class:`Ledger`).  A frame for a link of another host goes into that host's
book when it is published, with the host's daemons alive then; a report that covers its number
settles it: heard (nothing more to say here: that host traces what becomes of it), or traced here as an
``err`` of the sending link with the frame's ``pkt``, its destination link and one of three causes:

- ``net_lost``: the daemon that was up when it went on air never heard it (a link down, a host frozen
  past the lease, a message Zenoh dropped);
- ``host_down``: the host was down when it went on air (traced at once, as before: nobody there to
  hear it), or its daemon stopped before the frame arrived (said in its last report);
- ``unconfirmed``: that daemon vanished (killed) without a last report, and what comes after it (its
  successor's first report, or this daemon's own stop) cannot tell whether it arrived before it died.

A frame is so traced once, by its sender; a receiver that hears a number it already reported as never
heard does not deliver it (counted ``settled_late``).  Application frames only: a MAC's control frames
show their losses in the MAC's own events.  Broadcasts count for every link of the host on their channel.
"""

from __future__ import annotations

import bisect
import json
import logging
from collections import OrderedDict
from typing import Any, Callable, Iterable

from .netcodec import NetError, ReplayWindow, _integer, _loads, _text

log = logging.getLogger(__name__)

__all__ = ["Ledger", "Receipts", "encode_report", "decode_report", "REPORT_S", "REPEAT_S", "MAX_RANGES"]

REPORT_S = 0.2
"""How often a receiver reports what it settled (wall seconds): the sender's book holds about this
much traffic more than the frames on the way."""
REPEAT_S = 2.0  # a report is repeated this often while nothing changes (the last one may have been lost)
MAX_RANGES = 256  # never-heard ranges a report carries (cumulative): ~5 kB at most
MAX_REPORT = 16384  # bytes: a longer report is refused unread
MAX_PENDING = 1 << 16
"""Frames a sender keeps per host for a report to settle (a host silent that long: the oldest are traced
``unconfirmed``): at 100 frames/s, 11 minutes of a host that never reports."""
Ranges = list[list[int]]


def encode_report(host: str, zid: str, session: str, epoch_ns: int, low: int, upto: int, missed: Ranges,
                  stopped: Ranges, final: bool) -> bytes:
    return json.dumps({"h": host, "z": zid, "s": session, "e": epoch_ns, "l": low, "u": upto, "m": missed,
                       "x": stopped, "f": final}, separators=(",", ":")).encode()


def decode_report(data: bytes) -> dict[str, Any]:
    """A report from another host, checked field by field (:class:`~.netcodec.NetError`: ``bad_message``)."""
    if len(data) > MAX_REPORT:
        raise NetError("a report that long")
    message = _loads(data)
    if not isinstance(message, dict):
        raise NetError("a report is an object")
    report = {"host": _text(message, "h"), "zid": _text(message, "z"), "session": _text(message, "s"),
              "epoch_ns": _integer(message, "e"), "low": _integer(message, "l", 1, 2**63),
              "upto": _integer(message, "u", 0, 2**63), "missed": _ranges(message, "m"),
              "stopped": _ranges(message, "x"), "final": message.get("f") is True}
    if report["low"] > report["upto"] + 1:
        raise NetError("a report's ranges start after its end")
    return report


def _ranges(message: dict, key: str) -> Ranges:
    value = message.get(key)
    if not isinstance(value, list) or len(value) > MAX_RANGES:
        raise NetError(f"{key!r} is not a list of at most {MAX_RANGES} ranges")
    ranges = []
    for item in value:
        if (not isinstance(item, list) or len(item) != 2 or not all(type(n) is int for n in item)
                or not 1 <= item[0] <= item[1] < 2**63):
            raise NetError(f"{key!r} holds something that is not a range of numbers")
        ranges.append(item)
    return ranges


def _add(ranges: Ranges, first: int, last: int) -> None:
    """Append ``first..last`` (above every range already there), joined to the last one if adjacent."""
    if ranges and ranges[-1][1] + 1 >= first:
        ranges[-1][1] = max(ranges[-1][1], last)
    else:
        ranges.append([first, last])


def _within(ranges: Ranges, number: int) -> bool:
    i = bisect.bisect_right(ranges, [number, 2**63]) - 1
    return i >= 0 and ranges[i][0] <= number <= ranges[i][1]


class Receipts:
    """What this daemon heard of one session of another host (its Zenoh session and epoch), and the
    reports it owes that host."""

    __slots__ = ("session", "epoch_ns", "low", "upto", "heard", "ends", "missed", "stopped", "sent_upto",
                 "sent_at", "started", "aside")

    def __init__(self, session: str, epoch_ns: int):
        self.session = session
        self.epoch_ns = epoch_ns
        self.low = 1  # the reports cover the numbers from here (older ranges were let go)
        self.upto = 0  # every number up to this one is settled here
        self.heard: list[int] = []  # heard numbers above ``upto``, ascending
        self.ends: dict[int, float] = {}  # ... and the model time their last arrival here ends
        self.missed: Ranges = []  # never heard, within [low, upto]
        self.stopped: Ranges = []  # heard, but this daemon stopped before they arrived (its last report)
        self.sent_upto = -1
        self.sent_at = float("-inf")
        self.started = False
        # runs of numbers heard far ahead of the others (more than the replay window's WINDOW): each
        # [its numbers → their ends, the highest number heard below them when it began], kept aside
        self.aside: list[list[Any]] = []

    def heard_one(self, number: int, end: float) -> bool:
        """A transmission numbered ``number`` is handed to the medium; its arrivals here end at ``end``.
        False: it was already reported as never heard (the sender has traced it): do not deliver it.

        A number far ahead is kept aside, as the replay window keeps it in a run of its own (issue 37):
        settled, it would say every number below it was never heard, and the host's next frames would be
        refused here (one forged message with the host's key silenced it).  It joins the others when they
        reach it, or when its run goes on while they stand still (the host's numbers did jump: a cut,
        messages Zenoh or the hand-over dropped)."""
        if not self.started:
            self.started = True
            if number > 1:  # this daemon was not there for the numbers before
                _add(self.missed, 1, number - 1)
                self.upto = number - 1
        if number <= self.upto:
            return False
        if number in self.ends:
            return True  # (the replay window refuses a number twice; this is only belt and braces)
        top = self.heard[-1] if self.heard else self.upto
        if number > top + ReplayWindow.WINDOW:
            self._aside(number, end, top)
            return True
        self._record(number, end)
        for run in [run for run in self.aside if min(run[0]) <= number + 1]:  # reached from below
            self.aside.remove(run)
            for n, e in run[0].items():
                self._record(n, e)
        return True

    def _record(self, number: int, end: float) -> None:
        if number <= self.upto or number in self.ends:
            return
        if not self.heard or number > self.heard[-1]:
            self.heard.append(number)
        else:
            bisect.insort(self.heard, number)
        self.ends[number] = end

    def _aside(self, number: int, end: float, top: int) -> None:
        for run in self.aside:
            ends = run[0]
            if abs(number - max(ends)) <= ReplayWindow.WINDOW:  # (this run's)
                ends.setdefault(number, end)
                if len(ends) > ReplayWindow.WINDOW:
                    del ends[min(ends)]
                if run[1] == top:  # the others stood still meanwhile: the host's numbers jumped
                    self.aside.remove(run)
                    for n in sorted(ends):
                        self._record(n, ends[n])
                return
        if len(self.aside) >= ReplayWindow.RUNS:
            del self.aside[0]  # (forgotten: a number of it is reported never heard once the others pass it)
        self.aside.append([{number: end}, top])

    def settle(self, now: float, final: bool = False) -> None:
        """Move ``upto`` over every number settled by ``now`` (model time: arrivals that ended before
        it have their outcome in the trace).  ``final``: this daemon stops, nothing heard will arrive."""
        heard, ends = self.heard, self.ends
        done = 0
        for number in heard:
            if number > self.upto + 1:
                _add(self.missed, self.upto + 1, number - 1)
            if ends[number] < now:
                pass
            elif final:
                _add(self.stopped, number, number)
            else:
                self.upto = max(self.upto, number - 1)
                break
            del ends[number]
            self.upto = number
            done += 1
        del heard[:done]
        excess = len(self.missed) + len(self.stopped) - MAX_RANGES
        while excess > 0:  # let the oldest range go (the sender traces what is older as unconfirmed)
            oldest = self.missed if not self.stopped or (self.missed and self.missed[0][0] < self.stopped[0][0]) \
                else self.stopped
            self.low = oldest.pop(0)[1] + 1
            excess -= 1

    def report(self, host: str, zid: str, now: float, wall: float, final: bool = False) -> bytes | None:
        """The report to send now (None: nothing new, and the last one is recent)."""
        self.settle(now, final)
        if not final and self.upto == self.sent_upto and wall - self.sent_at < REPEAT_S:
            return None
        if self.upto == 0 and not final:
            return None
        self.sent_upto, self.sent_at = self.upto, wall
        low = max(self.low, 1)
        return encode_report(host, zid, self.session, self.epoch_ns, low, self.upto, self.missed, self.stopped, final)


class _Entry:
    __slots__ = ("src", "pkt", "size", "targets", "zids")

    def __init__(self, src: str, pkt: int, size: int, targets: tuple[str, ...], zids: frozenset[str]):
        self.src = src
        self.pkt = pkt
        self.size = size
        self.targets = targets
        self.zids = zids


Lost = Callable[[str, int, int, str, str, str], None]
"""``lost(src_link, pkt, size, dst_link, host, cause)``: trace and count one frame that did not reach
``dst_link`` on ``host``."""


class Ledger:
    """This daemon's frames for the links of other hosts, until each host's reports settle them."""

    def __init__(self, lost: Lost):
        self.lost = lost
        self.books: dict[str, OrderedDict[int, _Entry]] = {}
        self.finished: set[str] = set()  # daemons (Zenoh ids) that said their last report
        self._zids: dict[str, frozenset[str]] = {}
        self.counters = {"net_lost": 0, "host_down": 0, "unconfirmed": 0}

    def alive(self, host: str, zids: Iterable[str]) -> None:
        """The daemons of ``host`` alive now (its liveliness tokens)."""
        self._zids[host] = frozenset(zids)

    def down(self, src: str, pkt: int, size: int, targets: Iterable[str], host: str) -> None:
        """A frame for ``host``'s links that nobody there can hear (the host is down, or nobody there subscribes)."""
        for target in targets:
            self._lost(src, pkt, size, target, host, "host_down")

    def published(self, host: str, number: int, src: str, pkt: int, size: int, targets: tuple[str, ...]) -> None:
        """A frame for ``host``'s links went out as message ``number``: kept until a report settles it."""
        zids = self._zids.get(host, frozenset())
        if zids and zids <= self.finished:  # its daemon said its last word: the token goes next
            self.down(src, pkt, size, targets, host)
            return
        book = self.books.get(host)
        if book is None:
            book = self.books[host] = OrderedDict()
        book[number] = _Entry(src, pkt, size, targets, zids)
        if len(book) > MAX_PENDING:
            _, entry = book.popitem(last=False)
            self._trace(entry, host, "unconfirmed")

    def report(self, host: str, report: dict[str, Any]) -> None:
        """A report of ``host`` about this daemon's session: settle what it covers."""
        book = self.books.get(host)
        zid, upto, missed, stopped = report["zid"], report["upto"], report["missed"], report["stopped"]
        if report["final"]:
            self.finished.add(zid)
        if not book:
            return
        while book:
            number = next(iter(book))
            if number > upto:
                break
            entry = book.pop(number)
            if number < report["low"]:
                self._trace(entry, host, "unconfirmed")  # older than the report remembers: it cannot say
            elif _within(stopped, number):
                self._trace(entry, host, "host_down")
            elif _within(missed, number):
                others = entry.zids - {zid} - self.finished  # another daemon of the host might have had it
                self._trace(entry, host, "net_lost" if zid in entry.zids and not others else "unconfirmed")
        if report["final"]:  # what went out after its last report will never be heard by it
            for number in [n for n, entry in book.items() if entry.zids and entry.zids <= self.finished]:
                self._trace(book.pop(number), host, "host_down")

    def close(self) -> None:
        """This daemon stops: what no report settled is unconfirmed."""
        for host, book in self.books.items():
            while book:
                _, entry = book.popitem(last=False)
                self._trace(entry, host, "unconfirmed")

    def pending(self, hosts: Iterable[str] | None = None) -> int:
        """Frames not yet settled (for ``hosts`` only, if given)."""
        if hosts is None:
            return sum(len(book) for book in self.books.values())
        return sum(len(self.books.get(host, ())) for host in hosts)

    def _trace(self, entry: _Entry, host: str, cause: str) -> None:
        for target in entry.targets:
            self._lost(entry.src, entry.pkt, entry.size, target, host, cause)

    def _lost(self, src: str, pkt: int, size: int, target: str, host: str, cause: str) -> None:
        self.counters[cause] += 1
        try:
            self.lost(src, pkt, size, target, host, cause)
        except Exception:  # a bug in tracing must not leave the book half settled
            log.exception("tracing a frame lost between hosts")
