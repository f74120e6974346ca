"""What the operator's page draws, as plain JSON: the scene (vehicles, links and their modems) and the
frames in flight with their fates, from events in the trace's own vocabulary.

The live daemon (:mod:`hilgate.daemon.webfeed`) and the trace player (:mod:`.replay`) build their
messages here, so the page cannot tell which one it draws.  Sans-I/O: no sockets, threads or clock;
every number that reaches the page is finite (a trace may hold anything a reader let through).

A frame is drawn from its latest transmission until its wave has passed the sender's range
(``reach_s``), and each judgement (``rx``, or a loss with its cause; a FIFO drop at the sender) for
``linger_s`` after it.  The page only needs the sender's vehicle, the channel's speed and these times.
"""

from __future__ import annotations

import math
from collections import OrderedDict, deque
from typing import Any, Iterable

from ..report.causes import CAUSES, RECEIVED

__all__ = ["link_kind", "fates", "scene_message", "reach_s", "extent_m", "frame_view", "Flight", "LINGER_S", "MAX_FRAMES",
           "MAX_FLIGHT_S", "ERRORS_KEPT"]

LINGER_S = 2.0
"""Model seconds a judged frame's fate stays on the picture (at 1×)."""

MAX_FRAMES = 300
"""Frames in one picture (the newest): more would be a blur on any screen, and cost the daemon."""

MAX_FLIGHT_S = 30.0
"""The longest a wave is drawn (unbounded range, a slow channel): 45 km of water."""

UNBOUNDED_REACH_M = 10_000.0
"""How far a wave is drawn when no vehicle's position is known."""

STALE_S = 5.0
"""Model seconds after it can no longer be drawn that a live frame is forgotten (a late judgement, an rx
delay, comes within them)."""

ERRORS_KEPT = 5
"""A link's last errors shown in its row."""

MAX_OUTCOMES = 32
"""Judgements of one frame in a picture (a broadcast heard by a hundred modems shows the first ones)."""

DEFAULT_SPEED_MPS = 1500.0


def _number(value: Any, default: float | None) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return default
    return float(value)


def _text(value: Any) -> str:
    return value if isinstance(value, str) else str(value)


def link_kind(link: dict[str, Any]) -> str:
    """``sim``, ``real`` (a driver: EvoLogics, S100) or ``emulated`` (a simulated modem shown as a device)."""
    if link.get("emulate"):
        return "emulated"
    return "sim" if link.get("backend") == "sim" else "real"


def fates() -> dict[str, list[str]]:
    """What the page calls each fate of a frame and draws it in: ``rx`` and every loss cause, from the
    table the report uses (the page keeps no words of its own, so the two cannot read differently)."""
    return {"rx": [RECEIVED.words, RECEIVED.colour], **{code: [c.words, c.colour] for code, c in CAUSES.items()}}


def scene_message(view: dict[str, Any], mode: str) -> dict[str, Any]:
    """The page's SCENE from a scene view (:func:`hilgate.scene.view.scene_view`, or a trace's ``run``
    and ``reload`` lines): per link its vehicle, backend kind, channel speed, range, bit rate, FIFO size;
    and the words and colours of frames' fates."""
    channels = view.get("channels") if isinstance(view.get("channels"), dict) else {}
    links: dict[str, Any] = {}
    raw_links = view.get("links") if isinstance(view.get("links"), dict) else {}
    for link_id, link in raw_links.items():
        if isinstance(link, dict):
            links[_text(link_id)] = _scene_link(link, channels)
    raw_vehicles = view.get("vehicles") if isinstance(view.get("vehicles"), dict) else {}
    vehicles = {}
    for name, vehicle in raw_vehicles.items():
        vehicle = vehicle if isinstance(vehicle, dict) else {}
        vehicles[_text(name)] = {"source": _text(vehicle.get("source", "?")),
                                 "host": vehicle.get("host") if isinstance(vehicle.get("host"), str) else None}
    for link in links.values():  # (a hand-made view may name a vehicle it does not list)
        vehicles.setdefault(link["vehicle"], {"source": "?", "host": None})
    hosts = sorted({link["host"] for link in links.values() if link["host"]})
    return {"class": "SCENE", "mode": mode, "name": _text(view.get("name", "?")), "links": links,
            "vehicles": vehicles, "hosts": hosts, "fates": fates()}


def _scene_link(link: dict[str, Any], channels: dict[str, Any]) -> dict[str, Any]:
    """One link of the page's SCENE, from its scene view and its channels' (anything malformed read as unknown)."""
    params = link.get("params") if isinstance(link.get("params"), dict) else {}
    channel_name = link.get("tx_channel")
    channel = channels.get(channel_name) if isinstance(channel_name, str) else None
    channel = channel if isinstance(channel, dict) else {}
    span = params.get("range_m") if isinstance(params.get("range_m"), list) else []
    rmin = _number(span[0], 0.0) if len(span) > 0 else 0.0
    rmax = _number(span[1], None) if len(span) > 1 else None
    speed = _number(channel.get("speed_mps"), DEFAULT_SPEED_MPS)
    return {
        "vehicle": _text(link.get("vehicle")),
        "backend": _text(link.get("backend")),
        "kind": link_kind(link),
        "channel": _text(channel_name),
        "speed_mps": speed if speed and speed > 0 else DEFAULT_SPEED_MPS,
        "min_delay_s": max(0.0, _number(channel.get("min_delay_s"), 0.0)),
        "range_m": [max(0.0, rmin), rmax if rmax is None or rmax > 0 else None],
        "bitrate_bps": _number(params.get("bitrate_bps"), None),
        "fifo_bytes": _number(params.get("fifo_bytes"), None),
        "address": link.get("address") if isinstance(link.get("address"), int) else None,
        "host": link.get("host") if isinstance(link.get("host"), str) else None,
        "emulate": _text(link["emulate"].get("protocol", "modem")) if isinstance(link.get("emulate"), dict) else None,
    }


def reach_s(link: dict[str, Any] | None, size: int, extent_m: float = UNBOUNDED_REACH_M) -> float:
    """How long a frame of ``size`` bytes from ``link`` (a SCENE entry) is drawn in flight: until its wave
    has passed the modem's range, or the farthest vehicle (``extent_m``: the scene's span)."""
    if link is None:
        return LINGER_S
    rmax = link["range_m"][1]
    distance = min(rmax, extent_m) if rmax is not None else extent_m
    airtime = size * 8.0 / link["bitrate_bps"] if link.get("bitrate_bps") else 0.0
    return min(MAX_FLIGHT_S, link["min_delay_s"] + distance / link["speed_mps"] + airtime)


def frame_view(pkt: Any, src: str, dst: str, size: int, txs: Iterable[float],
               outcomes: Iterable[tuple[float, str, str, str | None]], now: float, reach: float,
               linger: float, kind: str = "data", floor: float = 0.0) -> dict[str, Any] | None:
    """One frame as the page draws it at ``now``, or None when nothing of it is on the picture: its latest
    transmission up to ``now`` (drawn while ``now - tx <= reach``, and in any case while ``now - tx <=
    floor``: a wave shorter than the time between two pictures, a real modem's 30 ms, must reach the
    page in one, which draws it in slow motion) and its judgements up to ``now`` (``[link, t, ev, cause]``,
    drawn for ``linger`` after each)."""
    tx = None
    for t in txs:
        if t <= now and (tx is None or t > tx):
            tx = t
    shown = []
    recent = False
    for t, link, ev, cause in outcomes:
        if t <= now:
            shown.append([link, round(t, 6), ev, cause])
            recent = recent or now - t <= linger
    flying = tx is not None and now - tx <= max(reach, floor)
    if not (flying or recent):
        return None
    if len(shown) > MAX_OUTCOMES:
        shown = shown[-MAX_OUTCOMES:]
    view = {"id": _text(pkt), "src": src, "dst": dst, "size": size,
            "tx": None if tx is None else round(tx, 6), "reach_s": round(reach, 6), "out": shown}
    if kind != "data":  # an acknowledgement, RTS or CTS: the page draws it only when asked to
        view["kind"] = kind
    return view


def extent_m(positions: Iterable[Any]) -> float:
    """How far a wave must go to pass every vehicle: the diagonal of their positions' box (at least 10 m)."""
    xs, ys, zs = [], [], []
    for position in positions:
        if position is not None:
            xs.append(position[0])
            ys.append(position[1])
            zs.append(position[2])
    if not xs:
        return UNBOUNDED_REACH_M
    return max(10.0, math.dist((min(xs), min(ys), min(zs)), (max(xs), max(ys), max(zs))))


class _Frame:
    __slots__ = ("pkt", "src", "dst", "size", "txs", "outcomes", "last", "kind")

    def __init__(self, pkt: Any, src: str, dst: str, size: int, t: float, kind: str = "data"):
        self.pkt, self.src, self.dst, self.size, self.kind = pkt, src, dst, size, kind
        self.txs: list[float] = []
        self.outcomes: list[tuple[float, str, str, str | None]] = []
        self.last = t


class Flight:
    """The live daemon's frames of the last seconds and each link's last errors, fed event by event
    (the recorder's tap while a page is connected).  Bounded: at most ``max_frames`` frames are
    remembered (the oldest go first) and ``ERRORS_KEPT`` errors per link."""

    def __init__(self, links: dict[str, Any] | None = None, max_frames: int = 4 * MAX_FRAMES):
        self.links: dict[str, Any] = links or {}
        self.extent_m = UNBOUNDED_REACH_M  # the vehicles' span: the daemon sets it with every picture
        self.max_frames = max_frames
        self.frames: OrderedDict[Any, _Frame] = OrderedDict()
        self.errors: dict[str, deque] = {}
        self._real = 0

    def clear(self) -> None:
        self.frames.clear()
        self.errors.clear()

    def _frame(self, pkt: Any, src: str, dst: str, size: int, t: float, kind: str = "data") -> _Frame:
        frame = self.frames.get(pkt)
        if frame is None:
            frame = self.frames[pkt] = _Frame(pkt, src, dst, size, t, kind)
            if len(self.frames) > self.max_frames:
                self.frames.popitem(last=False)
        frame.last = t
        return frame

    def _error(self, link: str, t: float, cause: str, detail: str = "") -> None:
        errors = self.errors.get(link)
        if errors is None:
            errors = self.errors[link] = deque(maxlen=ERRORS_KEPT)
        errors.append([round(t, 3), cause, detail])

    def frame(self, ev: str, t: float, link: str, pkt: Any, src: str, dst: str, size: int,
              cause: str | None, kind: str = "data") -> None:
        """A simulated modem's event (``enq``, ``drop``, ``tx``, ``rx``, ``err``) of frame ``pkt`` (a data
        frame, or a control frame of ``kind``: its losses are no link's errors)."""
        if ev == "enq":
            return  # queued: the FIFO's fill shows it; the frame is drawn from its transmission
        frame = self._frame(("c", pkt) if kind != "data" else pkt, src, dst, size, t, kind)
        if ev == "tx":
            frame.txs.append(t)
            del frame.txs[:-4]
        else:
            frame.outcomes.append((t, link, ev, cause))
            del frame.outcomes[:-MAX_OUTCOMES]
            if cause is not None and kind == "data":
                self._error(link, t, cause, f"from {src}")

    def line(self, record: dict[str, Any]) -> None:
        """A free-form trace line: a real modem's ``tx``/``rx`` (no frame id: drawn as a wave from its
        vehicle and a mark at the receiver), the GLI's losses and a modem's errors (the link's last errors)."""
        ev, link, t = record.get("ev"), record.get("link"), record.get("t")
        if not isinstance(link, str) or _number(t, None) is None:
            return
        cause = record.get("cause")
        if ev == "modem_error":
            self._error(link, t, "modem", _text(record.get("error", record.get("text", "")))[:120])
        elif ev in ("drop", "err") and isinstance(cause, str):
            src = record.get("src")
            self._error(link, t, cause, f"from {src}" if isinstance(src, str) and src not in ("medium",) else "")
        elif ev in ("tx", "rx") and "pkt" not in record:
            self._real += 1
            size = record.get("size") if isinstance(record.get("size"), int) else 0
            if ev == "tx":
                self._frame(f"{link}#{self._real}", link, "", size, t).txs.append(t)
            else:
                src = record.get("src")
                frame = self._frame(f"{link}#{self._real}", _text(src) if src is not None else "?", link, size, t)
                frame.outcomes.append((t, link, "rx", None))

    def visible(self, now: float, linger: float = LINGER_S, floor: float = 0.0) -> list[dict[str, Any]]:
        """The frames on the picture at ``now``, newest first (at most ``MAX_FRAMES``); the oldest frames,
        once nothing of them can be drawn any more, are forgotten.  ``floor``: model seconds a wave is
        sent in any case (:func:`frame_view`)."""
        frames, links, extent = self.frames, self.links, self.extent_m
        while frames:
            frame = frames[next(iter(frames))]
            if now - frame.last <= max(reach_s(links.get(frame.src), frame.size, extent), floor) + linger + STALE_S:
                break
            frames.popitem(last=False)
        out = []
        for frame in reversed(frames.values()):
            pkt = frame.pkt[1] if frame.kind != "data" else frame.pkt
            view = frame_view(f"{frame.kind}:{pkt}" if frame.kind != "data" else pkt, frame.src, frame.dst,
                              frame.size, frame.txs, frame.outcomes, now,
                              reach_s(links.get(frame.src), frame.size, extent), linger, frame.kind, floor)
            if view is not None:
                out.append(view)
                if len(out) >= MAX_FRAMES:
                    break
        return out

    def errors_of(self, link: str) -> list[list]:
        return list(self.errors.get(link, ()))
