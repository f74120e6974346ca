"""The soak's account (soak.py): every frame its applications sent, delivered or traced with its cause.

A frame is (sending link, number).  Its applications' logs (soak_app.py) say which connection sent it,
where to, when, and what every application received; the daemons' traces say what they did with it:

- the frame's ``pkt``: the n-th frame a connection sent is the n-th ``enq`` of that link in the trace
  of the daemon the connection was to (a daemon started again numbers its frames from 1 again);
- its causes: an ``err`` or ``drop`` line with a ``pkt`` about it: on the sending daemon's trace (``link``
  and ``src`` its link: the FIFO, and what another host did not get: ``host_down``, ``net_lost``,
  ``unconfirmed``) or on the receiving host's (``link`` its destination: the channel's losses, with
  ``src`` its link, and the GLI's on delivery, ``src`` "medium"), matched by destination, ``pkt`` and
  time (the frame sent to that link with that ``pkt`` whose ``enq`` is nearest, within :data:`MATCH_S`:
  model times compare across hosts through their epochs; the sender's ``enq``, not the application's
  send, since a daemon that fell behind reads a frame late);
- delivered: its destination's application received its number from its address.

Then sent = delivered + lost by each cause, and what is neither (``unexplained``), traced yet delivered
(``overlap``: only ``unconfirmed`` may be), delivered twice or out of order are counted.  A
daemon's aggregate ``net_gap`` lines (messages it missed, not frames) are counted apart.
"""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from typing import Any, Iterable

MATCH_S = 300.0
"""(A daemon far behind hears a frame long after it went on air; a daemon started again numbers its frames
from 1 again, so the same ``pkt`` comes back one restart later: the nearest in time is the frame.)"""


@dataclass
class Run:
    """One daemon's run: its host, trace file, and the wall times it served (start, stop)."""

    host: str
    trace: str
    start: float
    stop: float = float("inf")


@dataclass
class Account:
    sent: int = 0
    delivered: int = 0
    lost: Counter = field(default_factory=Counter)
    unexplained: list = field(default_factory=list)
    overlap: Counter = field(default_factory=Counter)
    twice: int = 0
    out_of_order: int = 0
    not_taken: int = 0  # sent by an application, never taken by its daemon (no enq line)
    unmatched: Counter = field(default_factory=Counter)  # loss lines that match no frame sent
    net_gaps: int = 0
    several: int = 0  # lost frames traced with more than one cause (counted under the first)
    by_run: dict = field(default_factory=dict)

    @property
    def balanced(self) -> bool:
        return (not self.unexplained and not self.twice and not self.out_of_order and not self.not_taken
                and set(self.overlap) <= {"unconfirmed"})


def _events(path: str) -> Iterable[dict[str, Any]]:
    with open(path) as handle:
        for line in handle:
            try:
                yield json.loads(line)
            except ValueError:  # (a run killed mid-line)
                continue


def account(logs: list[dict[str, Any]], runs: list[Run], host_of: dict[str, str], address_of: dict[str, int]
            ) -> Account:
    """``logs``: the applications' (soak_app.py); ``runs``: every daemon's run; ``host_of``/``address_of``:
    each link's host and address."""
    result = Account()
    link_at = {address: link for link, address in address_of.items()}
    opened = {}  # (link, connection) → wall time it opened
    for log in logs:
        for link, number, wall in log["opened"]:
            opened[(link, number)] = wall

    def run_of(link: str, wall: float) -> int:
        """The run of ``link``'s host that served at ``wall``."""
        host = host_of[link]
        return next(i for i, run in enumerate(runs) if run.host == host and run.start <= wall <= run.stop)

    # the frames, by (run, link) in the order each connection sent them
    sent_by = defaultdict(list)  # (run, link) → [(link, number, destination link, wall)]
    for log in logs:
        for link, connection, number, destination, wall in log["sent"]:
            sent_by[(run_of(link, opened[(link, connection)]), link)].append(
                (link, number, link_at.get(destination), wall))
    result.sent = sum(len(frames) for frames in sent_by.values())
    frame_of: dict[tuple[int, str, int], tuple[str, int]] = {}  # (run, link, pkt) → frame
    to_link = defaultdict(list)  # (destination, pkt) → [(wall, frame, run)]
    losses = []  # (run index, event, wall)
    for index, run in enumerate(runs):
        enq = defaultdict(list)
        epoch = None
        for event in _events(run.trace):
            kind = event.get("ev")
            if kind == "enq":
                enq[event["link"]].append((event["pkt"], event["t"]))
            elif kind == "network" and epoch is None:
                epoch = event["epoch_ns"] * 1e-9
            elif kind in ("err", "drop") and "cause" in event:
                if event.get("link") == "*":
                    result.net_gaps += event.get("n", 1)
                elif "pkt" in event:
                    losses.append((index, event))
        result.by_run[index] = {"host": run.host, "epoch": epoch}
        for link, taken in enq.items():
            frames = sent_by.get((index, link), [])
            result.not_taken += max(0, len(frames) - len(taken))
            for (pkt, t), (name, number, destination, _) in zip(taken, frames):
                frame_of[(index, link, pkt)] = (name, number)
                to_link[(destination, pkt)].append(((epoch or 0.0) + t, (name, number), index))
    causes: dict[tuple[str, int], list[str]] = defaultdict(list)
    for index, event in losses:
        link, src, pkt = event["link"], event.get("src"), event["pkt"]
        frame = frame_of.get((index, link, pkt)) if src == link else None
        if frame is None:  # on the receiving host: the frame sent to this link with this pkt, nearest in time
            epoch = result.by_run[index]["epoch"] or 0.0
            wall = epoch + event["t"]
            candidates = [(abs(wall - sent), frame, run) for sent, frame, run in to_link.get((link, pkt), ())
                          if src in ("medium", frame[0]) and abs(wall - sent) <= MATCH_S]
            frame = min(candidates)[1] if candidates else None
        if frame is None:
            result.unmatched[event["cause"]] += 1
            continue
        causes[frame].append(event["cause"])
    delivered = set()
    for log in logs:
        last: dict[tuple[str, str], int] = {}
        for link, source, number, wall in log["got"]:
            sender = link_at.get(source)
            frame = (sender, number)
            if frame in delivered:
                result.twice += 1
            if number <= last.get((link, sender), -1):
                result.out_of_order += 1
            last[(link, sender)] = number
            delivered.add(frame)
    result.delivered = len(delivered)
    for frames in sent_by.values():
        for name, number, destination, wall in frames:
            frame = (name, number)
            traced = causes.get(frame)
            if frame in delivered:
                for cause in set(traced or ()):
                    result.overlap[cause] += 1
            elif traced:
                result.lost[traced[0]] += 1
                result.several += len(set(traced)) > 1
            else:
                result.unexplained.append((name, number, destination, round(wall, 3)))
    return result
