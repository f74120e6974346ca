"""From a trace to what ``hilgate fit`` fits: one observation per frame heard or missed by a receiver,
with the distance between the two vehicles when it was sent.

Two sources of frames:

- **real links** (``backend: evologics`` / ``s100``): the driver traces ``tx`` at the sender (with the
  destination address for EvoLogics) and ``rx`` at the receiver (with the source address, RSSI and
  integrity for EvoLogics), but no frame id.  A frame sent by A counts as delivered to B when B
  traced an ``rx`` of the same size (and source address, when traced) within ``window_s`` after it,
  and no later frame of A to B took that ``rx`` (an ``rx`` belongs to the latest frame before it);
  else as lost.
- **simulated links** (``hilgate sim``, or the daemon's simulated links; only with ``simulated=True``):
  frames carry their id; ``rx`` is delivered, ``err`` cause ``prop`` is lost.

Losses that are not the channel's (``col``/``mult`` collisions, ``fifo`` drops, ``range``) are left
out and counted by cause, and so are frames with no pose sample of either vehicle within
``pose_gap_s`` of their time.  Distances come from the trace's ``pose`` samples, interpolated
linearly between the two samples around the time.  Nothing here knows the scene's file format:
the caller gives each link's vehicle, backend, address and channels (:class:`LinkInfo`).
"""

from __future__ import annotations

import bisect
import json
import math
from collections import Counter, defaultdict
from dataclasses import dataclass, field

__all__ = ["LinkInfo", "Observation", "Observations", "FitError", "read_events", "observations"]

BROADCAST = 255


class FitError(RuntimeError):
    """A trace ``hilgate fit`` cannot use; the message is one line and says what to do."""


@dataclass(frozen=True)
class LinkInfo:
    vehicle: str
    backend: str
    address: int
    tx_channel: str
    rx_channel: str


@dataclass(frozen=True)
class Observation:
    t: float
    src: str
    dst: str
    d: float
    size: int
    delivered: bool
    rssi: float | None = None
    integrity: float | None = None


@dataclass
class Observations:
    frames: list[Observation] = field(default_factory=list)
    excluded: Counter = field(default_factory=Counter)  # cause -> frames left out


def read_events(path: str, first_line: int = 1, last_line: int | None = None) -> list[dict]:
    """The JSON lines of a trace (one run's lines when given); a line cut short at the end is skipped."""
    events = []
    try:
        handle = open(path, encoding="utf-8")
    except OSError as exc:
        raise FitError(f"cannot read trace {path}: {exc.strerror}") from None
    with handle:
        for number, line in enumerate(handle, 1):
            if number < first_line or (last_line is not None and number > last_line):
                continue
            line = line.strip()
            if not line:
                continue
            try:
                events.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return events


class _Poses:
    def __init__(self, events: list[dict]):
        samples: dict[str, list[tuple[float, list[float]]]] = defaultdict(list)
        for event in events:
            if event.get("ev") == "pose" and event.get("position") is not None:
                samples[event["vehicle"]].append((float(event["t"]), event["position"]))
        self.samples = {name: sorted(s, key=lambda x: x[0]) for name, s in samples.items()}
        self.times = {name: [t for t, _ in s] for name, s in self.samples.items()}

    def __bool__(self) -> bool:
        return bool(self.samples)

    def position(self, vehicle: str, t: float, gap: float) -> list[float] | None:
        times = self.times.get(vehicle)
        if not times:
            return None
        samples = self.samples[vehicle]
        i = bisect.bisect_left(times, t)
        if i < len(times) and times[i] == t:
            return samples[i][1]
        before = samples[i - 1] if i > 0 else None
        after = samples[i] if i < len(samples) else None
        if before is not None and after is not None and after[0] - before[0] <= 2 * gap:
            w = (t - before[0]) / (after[0] - before[0])
            return [a + w * (b - a) for a, b in zip(before[1], after[1])]
        nearest = min((s for s in (before, after) if s is not None), key=lambda s: abs(s[0] - t))
        return nearest[1] if abs(nearest[0] - t) <= gap else None


def observations(events: list[dict], links: dict[str, LinkInfo], *, simulated: bool = False,
                 receivers: set[str] | None = None, pose_gap_s: float = 2.0, window_s: float = 5.0) -> Observations:
    """Every frame a receiver of ``receivers`` (default: all) heard or missed, with its distance."""
    poses = _Poses(events)
    if not poses:
        raise FitError("the trace has no pose samples, so no distances (the scene's trace: {poses_s} is on by "
                       "default; real vehicles need a pose source)")
    real = {name for name, link in links.items() if link.backend != "sim"}
    real_tx = [e for e in events if e.get("ev") == "tx" and e.get("link") in real]
    if not simulated and not real_tx:
        raise FitError("the trace has no frames sent by real links (backend evologics or s100); "
                       "to fit a simulated run's trace, say so with --simulated")
    out = Observations()
    wanted = receivers if receivers is not None else set(links)

    def observe(t: float, src: str, dst: str, size: int, delivered: bool, rx: dict | None = None) -> None:
        a = poses.position(links[src].vehicle, t, pose_gap_s)
        b = poses.position(links[dst].vehicle, t, pose_gap_s)
        if a is None or b is None:
            out.excluded["no pose"] += 1
            return
        rssi = rx.get("rssi") if rx else None
        integrity = rx.get("integrity") if rx else None
        out.frames.append(Observation(t, src, dst, math.dist(a, b), size, delivered, rssi, integrity))

    if simulated:
        _simulated(events, links, wanted, observe, out)
    else:
        _real(events, links, real, wanted, observe, out, window_s)
    return out


def _simulated(events, links, wanted, observe, out: Observations) -> None:
    sent: dict[int, list[float]] = defaultdict(list)
    for event in events:
        pkt = event.get("pkt")
        if pkt is None:
            continue
        ev = event.get("ev")
        if ev == "tx":
            sent[pkt].append(float(event["t"]))
        elif ev == "drop" and event.get("cause") == "fifo":
            out.excluded["fifo"] += 1
        elif ev in ("rx", "err") and event.get("link") in wanted and event.get("src") in links:
            cause = event.get("cause")
            if ev == "err" and cause != "prop":
                out.excluded[{"col": "collision", "mult": "collision"}.get(cause, cause)] += 1
                continue
            t = float(event["t"])
            times = [x for x in sent.get(pkt, ()) if x <= t]
            if not times:
                out.excluded["no tx"] += 1
                continue
            observe(times[-1], event["src"], event["link"], int(event["size"]), ev == "rx")


def _real(events, links, real, wanted, observe, out: Observations, window_s: float) -> None:
    """Each ``rx`` belongs to the latest frame sent to that receiver before it, by the sender its
    source address names, of its size, within ``window_s`` and not yet matched; every frame sent and
    not matched was lost (on the way to each receiver it was for)."""
    by_address = {(link.rx_channel, link.address): name for name, link in links.items() if name in real}
    sent: list[list] = []  # [t, src, dst, size, rx event or None], in time order
    open_frames: dict[str, list[list]] = defaultdict(list)  # receiver -> frames not matched yet
    for event in events:
        ev, link = event.get("ev"), event.get("link")
        if link not in real:
            continue
        if ev == "tx":
            t = float(event["t"])
            sender = links[link]
            dst_addr = event.get("dst")
            if dst_addr is None or dst_addr == BROADCAST:
                targets = [name for name in real if name != link and links[name].rx_channel == sender.tx_channel]
            else:
                target = by_address.get((sender.tx_channel, int(dst_addr)))
                targets = [target] if target is not None else []
            for dst in targets:
                if dst in wanted:
                    frame = [t, link, dst, int(event.get("size", 0)), None]
                    sent.append(frame)
                    open_frames[dst].append(frame)
        elif ev == "rx" and link in wanted:
            t = float(event["t"])
            src_addr = event.get("src")
            size = int(event.get("size", -1))
            candidates = open_frames[link]
            for i in range(len(candidates) - 1, -1, -1):
                frame = candidates[i]
                if frame[0] > t or frame[3] != size:
                    continue
                if t - frame[0] > window_s:
                    break
                if src_addr is None or int(src_addr) == links[frame[1]].address:
                    frame[4] = event
                    del candidates[i]
                    break
            if len(candidates) > 64:  # frames older than the window can no longer be matched
                candidates[:] = [f for f in candidates if t - f[0] <= window_s]
        elif ev == "drop" and event.get("cause") in ("queue_full", "down", "closed"):
            out.excluded[str(event["cause"])] += 1
    for t, src, dst, size, rx in sent:
        observe(t, src, dst, size, rx is not None, rx)
