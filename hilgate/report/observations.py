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

**Which links are real, and where they ride, is read from the trace as it goes**: the daemon's ``run``
line and every ``reload`` line carry the scene (:mod:`hilgate.scene.view`), so a link that was real
for ten minutes of a run is fitted over those ten minutes, whatever the scene file says later.  A
caller that gives ``links`` with ``follow_scene=False`` (``--scene``) fixes them for the whole trace.

Losses that are not the channel's (``col``/``mult`` collisions, ``fifo`` drops, ``range``) are left
out and counted by cause, and so are frames with no pose sample of either vehicle within
``pose_gap_s`` of their time.  Distances come from the trace's ``pose`` samples, interpolated
linearly between the two samples around the time.

One pass over the events, each handled in bounded time (a receiver's open frames are indexed by
size and sender, and only the newest few are looked at), so a trace costs time linear in its size
however its times repeat; what is wrong in a line is a :class:`FitError` naming it.
"""

from __future__ import annotations

import bisect
import math
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator

from .tracefile import TraceError, count, describe, number, position, printable, read_lines, text

__all__ = ["LinkInfo", "Observation", "Observations", "FitError", "read_events", "observations", "links_of_view"]

BROADCAST = 255
SCAN = 64
"""Frames of one (receiver, size, sender) looked at for one ``rx``, newest first: the newest unmatched
one is nearly always the last, and the bound keeps a hostile trace linear."""
KEPT_TX = 16
"""Transmissions of one simulated frame id kept (a frame is retransmitted a few times at most)."""


class FitError(TraceError):
    """A trace ``hilgate fit`` cannot use; the message is one line and says what to do."""


@dataclass(frozen=True)
class LinkInfo:
    vehicle: str
    backend: str
    address: int
    tx_channel: str
    rx_channel: str
    error: Any = field(default=None, compare=False)  # the view of its error model (scene/view.py)


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
    links: dict[str, LinkInfo] = field(default_factory=dict)  # every link the trace's scenes named, as last seen


def read_events(path: str, first_line: int = 1, last_line: int | None = None) -> Iterator[tuple[int, dict]]:
    """(line number, event) of a trace's lines (one run's, when given); see :mod:`.tracefile`."""
    return read_lines(path, first_line, last_line)


def links_of_view(view: Any, where: str) -> dict[str, LinkInfo]:
    """The links of a scene view (a ``run``/``reload`` line's ``scene_view``), checked."""
    links = view.get("links") if isinstance(view, dict) else None
    if not isinstance(links, dict):
        raise FitError(f"{where}: scene_view must be an object with the scene's links, not {describe(view)}")
    out = {}
    for name, link in links.items():
        if not isinstance(link, dict):
            raise FitError(f"{where}: scene_view link {describe(name)} must be an object, not {describe(link)}")
        at = f"{where}: scene_view link {describe(name)}"
        out[name] = LinkInfo(text(link, "vehicle", at), text(link, "backend", at), count(link, "address", at),
                             text(link, "tx_channel", at), text(link, "rx_channel", at),
                             (link.get("params") or {}).get("error") if isinstance(link.get("params"), dict) else None)
    return out


class _Poses:
    def __init__(self) -> None:
        self.samples: dict[str, list[tuple[float, list[float]]]] = defaultdict(list)
        self.times: dict[str, list[float]] = {}

    def add(self, vehicle: str, t: float, where: list[float]) -> None:
        self.samples[vehicle].append((t, where))

    def done(self) -> None:
        for name, samples in self.samples.items():
            samples.sort(key=lambda s: s[0])
            self.times[name] = [t for t, _ in samples]

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


class _Frame:
    """A frame sent to one receiver: matched to an ``rx`` or not (yet)."""

    __slots__ = ("t", "src", "dst", "size", "src_vehicle", "dst_vehicle", "delivered", "rx")

    def __init__(self, t: float, src: str, dst: str, size: int, src_vehicle: str, dst_vehicle: str,
                 delivered: bool = False, rx: dict | None = None):
        self.t, self.src, self.dst, self.size = t, src, dst, size
        self.src_vehicle, self.dst_vehicle = src_vehicle, dst_vehicle
        self.delivered, self.rx = delivered, rx


def _numbered(events: Iterable[Any], path: str) -> Iterator[tuple[str, dict]]:
    for index, item in enumerate(events, 1):
        number, event = item if isinstance(item, tuple) else (index, item)
        if not isinstance(event, dict):
            raise FitError(f"{path}:{number}: not a JSON object but {describe(event)}")
        yield f"{path}:{number}", event


def _address(value: Any, links: dict[str, LinkInfo], where: str, name: str) -> int | None:
    """A ``dst``/``src`` as the address it names: a number (a driver's line), ``"*"`` (broadcast), a link id
    or ``"addr:N"`` (the names a simulated modem's lines use); None when it names no address."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise FitError(f"{where}: {name!r} must be an address or a link id, not {describe(value)}")
    if isinstance(value, int):
        return value
    if value == "*":
        return BROADCAST
    if value in links:
        return links[value].address
    head, _, digits = value.partition(":")
    return int(digits) if head == "addr" and digits.isdigit() and len(digits) < 6 else None


def observations(events: Iterable[Any], links: dict[str, LinkInfo] | None = None, *, simulated: bool = False,
                 receivers: set[str] | None = None, pose_gap_s: float = 2.0, window_s: float = 5.0,
                 follow_scene: bool = True, path: str = "trace") -> Observations:
    """Every frame a receiver of ``receivers`` (default: all) heard or missed, with its distance.

    ``events``: dicts, or (line number, dict) pairs as :func:`read_events` gives them; ``links``: the
    scene's links at the start (None: only what the trace's scene lines say)."""
    out = Observations()
    matcher = _Real(window_s) if not simulated else _Simulated()
    current: dict[str, LinkInfo] = dict(links or {})
    out.links.update(current)
    matcher.scene(current)
    poses = _Poses()
    real_seen = False
    for where, event in _numbered(events, path):
        ev = event.get("ev")
        if ev in ("run", "reload"):
            if follow_scene and "scene_view" in event:
                current = links_of_view(event["scene_view"], where)
                out.links.update(current)
                matcher.scene(current)
            continue
        if ev == "pose":
            vehicle = text(event, "vehicle", where)
            spot = position(event, "position", where)
            t = number(event, "t", where)
            if spot is not None:
                poses.add(vehicle, t, spot)
            continue
        if ev not in ("tx", "rx", "err", "drop"):
            continue
        link = event.get("link")
        if not isinstance(link, str) or link not in current:
            continue
        if current[link].backend != "sim":
            real_seen = real_seen or ev == "tx"
        matcher.event(ev, link, event, where, current, receivers, out)
    poses.done()
    _check_enough(out, receivers, poses, simulated, real_seen)
    for frame in matcher.frames:
        a = poses.position(frame.src_vehicle, frame.t, pose_gap_s)
        b = poses.position(frame.dst_vehicle, frame.t, pose_gap_s)
        if a is None or b is None:
            out.excluded["no pose"] += 1
            continue
        rx = frame.rx
        out.frames.append(Observation(frame.t, frame.src, frame.dst, math.dist(a, b), frame.size, frame.delivered,
                                      _measure(rx, "rssi"), _measure(rx, "integrity")))
    return out


def _check_enough(out: Observations, receivers: set[str] | None, poses: "_Poses", simulated: bool,
                  real_seen: bool) -> None:
    """A fit needs the receivers asked for, pose samples, and (of a real run) frames sent by real links."""
    if receivers is not None:
        unknown = sorted(name for name in receivers if name not in out.links)
        if unknown:
            names = ", ".join(printable(name) for name in list(out.links)[:20]) or "none"
            raise FitError(f"no link {printable(unknown[0])!r} in the trace's scene; links: {names}")
    if not poses:
        raise FitError("the trace has no pose samples, so no distances (the scene's trace: {poses_s} is on by "
                       "default; real vehicles need a pose source)")
    if not simulated and not real_seen:
        raise FitError("the trace has no frames sent by real links (backend evologics or s100); "
                       "to fit a simulated run's trace, say so with --simulated")


def _measure(rx: dict | None, name: str) -> float | None:
    value = rx.get(name) if rx else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return value


class _Simulated:
    """Simulated frames carry their id: the ``rx`` or ``err`` of a frame at a receiver is its outcome."""

    def __init__(self) -> None:
        self.frames: list[_Frame] = []
        self.sent: dict[Any, list[float]] = {}

    def scene(self, links: dict[str, LinkInfo]) -> None:
        pass

    def event(self, ev: str, link: str, event: dict, where: str, links: dict[str, LinkInfo],
              wanted: set[str] | None, out: Observations) -> None:
        pkt = event.get("pkt")
        if pkt is None or links[link].backend != "sim":
            return
        if isinstance(pkt, (dict, list)):
            raise FitError(f"{where}: 'pkt' must be a frame id, not {describe(pkt)}")
        if ev == "tx":
            times = self.sent.setdefault(pkt, [])
            bisect.insort(times, number(event, "t", where))
            if len(times) > KEPT_TX:
                del times[0]
        elif ev == "drop" and event.get("cause") == "fifo":
            out.excluded["fifo"] += 1
        elif ev in ("rx", "err") and (wanted is None or link in wanted):
            src = event.get("src")
            if not isinstance(src, str) or src not in links:
                return
            cause = event.get("cause")
            if ev == "err" and cause != "prop":
                cause = text(event, "cause", where, "?")
                out.excluded[{"col": "collision", "mult": "collision"}.get(cause, cause)] += 1
                return
            t = number(event, "t", where)
            times = self.sent.get(pkt, ())
            i = bisect.bisect_right(times, t)
            if i == 0:
                out.excluded["no tx"] += 1
                return
            self.frames.append(_Frame(times[i - 1], src, link, count(event, "size", where), links[src].vehicle,
                                      links[link].vehicle, ev == "rx"))


class _Real:
    """Each ``rx`` belongs to the latest frame sent to that receiver before it, by the sender its
    source address names, of its size, within ``window_s`` and not yet matched; every frame sent and
    not matched was lost (on the way to each receiver it was for)."""

    def __init__(self, window_s: float):
        self.window = window_s
        self.frames: list[_Frame] = []
        self.by_sender: dict[tuple, list[_Frame]] = defaultdict(list)  # (receiver, size, sender) -> open frames
        self.by_size: dict[tuple, list[_Frame]] = defaultdict(list)    # (receiver, size) -> open frames
        self.senders: dict[tuple[str, int], str] = {}    # (channel, address) -> the real link sending there
        self.addressed: dict[tuple[str, int], str] = {}  # (channel, address) -> the real link listening there
        self.listeners: dict[str, list[str]] = {}        # channel -> the real links listening on it

    def scene(self, links: dict[str, LinkInfo]) -> None:
        real = {name: link for name, link in links.items() if link.backend != "sim"}
        self.senders = {(link.tx_channel, link.address): name for name, link in real.items()}
        self.addressed = {(link.rx_channel, link.address): name for name, link in real.items()}
        self.listeners = defaultdict(list)
        for name, link in real.items():
            self.listeners[link.rx_channel].append(name)

    def event(self, ev: str, link: str, event: dict, where: str, links: dict[str, LinkInfo],
              wanted: set[str] | None, out: Observations) -> None:
        info = links[link]
        if info.backend == "sim":
            return
        if ev == "tx":
            self._sent(link, info, event, where, links, wanted)
        elif ev == "rx" and (wanted is None or link in wanted):
            self._received(link, info, event, where, links)
        elif ev == "drop" and event.get("cause") in ("queue_full", "down", "closed"):
            out.excluded[str(event["cause"])] += 1

    def _sent(self, link: str, info: LinkInfo, event: dict, where: str, links: dict[str, LinkInfo],
              wanted: set[str] | None) -> None:
        """A real link's ``tx``: one open frame per real link it was for (its addressee, or every other
        listener on its channel for a broadcast), waiting for its ``rx``."""
        t = number(event, "t", where)
        size = count(event, "size", where, 0)
        address = _address(event.get("dst"), links, where, "dst")
        if address is None or address == BROADCAST:
            targets = [name for name in self.listeners.get(info.tx_channel, ()) if name != link]
        else:
            target = self.addressed.get((info.tx_channel, address))
            targets = [target] if target is not None and target != link else []
        for dst in targets:
            if wanted is None or dst in wanted:
                frame = _Frame(t, link, dst, size, info.vehicle, links[dst].vehicle)
                self.frames.append(frame)
                self.by_sender[(dst, size, link)].append(frame)
                self.by_size[(dst, size)].append(frame)

    def _received(self, link: str, info: LinkInfo, event: dict, where: str, links: dict[str, LinkInfo]) -> None:
        """A real link's ``rx``: matched to an open frame of its sender (the one its source address names)
        and size, or of its size alone when it names none."""
        t = number(event, "t", where)
        size = count(event, "size", where, -1)
        address = _address(event.get("src"), links, where, "src")
        if "src" in event and event.get("src") is not None:
            sender = self.senders.get((info.rx_channel, address)) if address is not None else None
            if sender is None:
                return  # from no real link of the scene
            candidates = self.by_sender.get((link, size, sender))
        else:
            candidates = self.by_size.get((link, size))
        if candidates:
            self._match(candidates, t, event)

    def _match(self, candidates: list[_Frame], t: float, rx: dict) -> None:
        while candidates and candidates[-1].delivered:  # matched through the other index
            candidates.pop()
        for i in range(len(candidates) - 1, max(-1, len(candidates) - 1 - SCAN), -1):
            frame = candidates[i]
            if frame.delivered or frame.t > t:
                continue
            if t - frame.t > self.window:
                return
            frame.delivered, frame.rx = True, rx
            del candidates[i]
            return
