"""One account per link id over the whole run, whatever its backend.

A reload may give a link another backend (``sim`` → ``evologics`` → ``sim``): each backend counts
from zero, and the simulated modem of a link that went real is gone.  The account keeps one
*segment* per backend period (start, end, backend, counts), so the link's totals survive every swap,
and the summary lists every link that existed during the run, even one a reload removed.

Nothing here is on the per-frame path: a segment reads the backend's and the link's own counters
when it opens and when it closes (a reload, the link removed, the end of the run), and the counts of
the segment are the difference.  Reading an open segment (``hilgate status``) reads the counters
once more.
"""

from __future__ import annotations

import datetime
from typing import Any, Callable

__all__ = ["COUNTS", "Counters", "Segment", "LinkAccount"]

COUNTS = ("tx_packets", "rx_packets", "drops", "unread_kept")
"""Counters that add up (a segment has the difference between its end and its start)."""

Counters = dict[str, Any]
"""What :meth:`hilgate.daemon.routed_link.RoutedLink.counters` reads: ``COUNTS``, ``drop_causes`` (the
link's GLI losses by cause) and ``fifo_peak_bytes`` (a simulated modem's, else None)."""


ZERO: Counters = {**dict.fromkeys(COUNTS, 0), "drop_causes": {}, "fifo_peak_bytes": None}


def _utc_now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="milliseconds")


class Segment:
    """One backend period of a link: open while ``end`` is None."""

    __slots__ = ("backend", "start", "since", "end", "_base", "_read", "_final")

    def __init__(self, backend: str, start: float, read: Callable[[], Counters], base: Counters | None = None):
        self.backend = backend
        self.start = start
        self.since = _utc_now()  # the wall clock, for people reading hilgate status
        self.end: float | None = None
        self._read = read
        self._base = base if base is not None else read()
        self._final: Counters | None = None

    def close(self, t: float) -> None:
        if self.end is None:
            self._final = self.counts()
            self.end = t
            self._read = None  # the backend is gone: nothing to keep alive

    def counts(self) -> Counters:
        """What the link counted in this period (so far, while it is open)."""
        if self._final is not None:
            return self._final
        now, base = self._read(), self._base
        counts: Counters = {key: now[key] - base[key] for key in COUNTS}
        causes = {cause: n - base["drop_causes"].get(cause, 0) for cause, n in now["drop_causes"].items()}
        counts["drop_causes"] = {cause: n for cause, n in causes.items() if n}
        counts["fifo_peak_bytes"] = now.get("fifo_peak_bytes")
        return counts

    def summary(self, now: float) -> dict[str, Any]:
        counts = self.counts()
        entry = {"backend": self.backend, "start_s": round(self.start, 9),
                 "end_s": round(self.end if self.end is not None else now, 9), "since": self.since,
                 "tx_packets": counts["tx_packets"], "rx_packets": counts["rx_packets"], "drops": counts["drops"],
                 "unread": counts["unread_kept"] + counts["drop_causes"].get("no_reader", 0),
                 "drop_causes": counts["drop_causes"]}
        if counts["fifo_peak_bytes"] is not None:
            entry["fifo_peak_bytes"] = counts["fifo_peak_bytes"]
        return entry


class LinkAccount:
    """Every backend period of one link id, in order; at most the last one is open."""

    def __init__(self, link_id: str):
        self.id = link_id
        self.segments: list[Segment] = []

    @property
    def current(self) -> Segment | None:
        last = self.segments[-1] if self.segments else None
        return last if last is not None and last.end is None else None

    def open(self, t: float, backend: str, read: Callable[[], Counters], from_zero: bool = False) -> Segment:
        """A new backend period from ``t`` (closing the one before at ``t``).  ``from_zero``: everything
        the counters hold is this period's (a link just built: what its doors counted while opening,
        frames left in its queues by an earlier run, belongs to it)."""
        self.close(t)
        segment = Segment(backend, t, read, ZERO if from_zero else None)
        self.segments.append(segment)
        return segment

    def close(self, t: float) -> None:
        current = self.current
        if current is not None:
            current.close(t)

    def totals(self) -> Counters:
        """The link's counts over the whole run so far."""
        totals: Counters = dict.fromkeys(COUNTS, 0)
        causes: dict[str, int] = {}
        peak = None
        for segment in self.segments:
            counts = segment.counts()
            for key in COUNTS:
                totals[key] += counts[key]
            for cause, n in counts["drop_causes"].items():
                causes[cause] = causes.get(cause, 0) + n
            if counts["fifo_peak_bytes"] is not None:
                peak = max(peak or 0, counts["fifo_peak_bytes"])
        totals["drop_causes"] = causes
        totals["fifo_peak_bytes"] = peak
        return totals

    def summary(self, now: float) -> dict[str, Any]:
        """The summary's entry for this link: totals first (the keys ``hilgate sim`` writes), then the
        backend it had last and one segment per backend period."""
        totals = self.totals()
        return {
            "id": self.id,
            "tx_packets": totals["tx_packets"],
            "rx_packets": totals["rx_packets"],
            "fifo_drops": totals["drops"],
            "fifo_peak_bytes": totals["fifo_peak_bytes"] or 0,
            "backend": self.segments[-1].backend if self.segments else None,
            "unread": totals["unread_kept"] + totals["drop_causes"].get("no_reader", 0),
            "drop_causes": totals["drop_causes"],
            "segments": [segment.summary(now) for segment in self.segments],
        }
