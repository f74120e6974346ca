"""A trace made ready to play: the picture at any model time, in time that does not grow with the trace.

``hilgate view TRACE`` reads the trace once with the reader ``hilgate report`` uses
(:func:`hilgate.report.tracedata.load_trace`: strict, one line naming what is wrong) and indexes it:

- every counter the page shows is a sorted list of event times, so its value at ``t`` is one bisection
  (seeking backwards costs what seeking forwards does);
- frames are put in one-second buckets over the interval they can be drawn in, so the frames on the
  picture at ``t`` are found among those of a few buckets;
- vehicles' positions are the trace's ``pose`` samples, interpolated linearly; the scene (which links
  are real, their ranges) is the ``run``/``reload`` line in force at ``t``.

The counters are ``hilgate report``'s: per flow the transmissions, receptions and losses by cause of
the frames that carry an id (a simulated modem's), as its timeline figure counts them.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import defaultdict
from typing import Any

from ..report.tracedata import Trace
from .events import trace_events
from .picture import ERRORS_KEPT, LINGER_S, MAX_FLIGHT_S, MAX_FRAMES, extent_m, frame_view, reach_s, scene_message

__all__ = ["Replay", "SPEEDS", "MIN_SPEED", "MAX_SPEED"]

BUCKET_S = 1.0
MIN_SPEED, MAX_SPEED = 0.1, 100.0
SPEEDS = (0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 25.0, 50.0, 100.0)
MAX_LINGER_S = 10.0
"""A fate is shown for two seconds of the viewer's time, but at most this long in model time (at 100× a
picture would otherwise hold 200 s of traffic)."""


class _Packet:
    __slots__ = ("pkt", "src", "dst", "size", "txs", "outcomes", "kind")


class Replay:
    """The pictures of one trace (one run of it).  ``scenes``: (t, scene view) in force from t, at least one."""

    def __init__(self, trace: Trace, scenes: list[tuple[float, dict]], name: str = ""):
        if not scenes:
            raise ValueError("a trace is played with the scene it ran: none given")
        self.name = name
        self.scenes = sorted(((t, scene_message(view, "replay")) for t, view in scenes), key=lambda s: s[0])
        self._scene_times = [t for t, _ in self.scenes]
        self.start = 0.0
        self.end = max(0.0, trace.end)
        self.packets: list[_Packet] = []
        self.buckets: dict[int, list[int]] = defaultdict(list)
        self.link_times: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
        self.flow_times: dict[tuple[str, str], dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
        self.errors: dict[str, list[tuple[float, str, str]]] = defaultdict(list)
        self.causes: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
        self.fifo = {link: _sorted_pairs(points) for link, points in trace.fifo.items()}
        self.poses = {vehicle: _sorted_pairs(points) for vehicle, points in trace.poses.items()}
        self.extent_m = extent_m(spot for _, spots in self.poses.values() for spot in spots)
        self._index(trace)
        self.hosts: dict[str, list[tuple[float, str]]] = defaultdict(list)
        for t, host, state in sorted(trace.hosts, key=lambda h: h[0]):
            self.hosts[host].append((t, state))
        losses = [(t, link, cause) for link, causes in self.causes.items() for cause, times in causes.items()
                  for t in times]
        self.events = trace_events(self.scenes, sorted(trace.hosts, key=lambda h: h[0]), self.poses, losses)

    # -- the index --------------------------------------------------------------------------------

    def _index(self, trace: Trace) -> None:
        for packet in [*trace.packets.values(), *trace.control.values()]:
            p = _Packet()
            p.pkt, p.src, p.dst, p.size, p.kind = packet.pkt, packet.src, packet.dst, packet.size, packet.kind
            p.txs = sorted(packet.t_tx)
            p.outcomes = sorted(packet.outcomes, key=lambda o: o[0])
            index = len(self.packets)
            self.packets.append(p)
            if p.kind == "data":  # control frames are drawn, never counted
                flow = self.flow_times[(p.src, p.dst)]
                flow["sent"].extend(p.txs)
                self.link_times[p.src]["tx"].extend(p.txs)
                for t, link, ev, cause in p.outcomes:
                    if ev == "rx":
                        flow["received"].append(t)
                        self.link_times[link]["rx"].append(t)
                    else:
                        flow["lost:" + (cause or "?")].append(t)
                        self.link_times[link]["drops" if ev == "drop" else "lost"].append(t)
                        self.causes[link][cause or "?"].append(t)
                        self.errors[link].append((t, cause or "?", f"from {p.src}"))
            times = p.txs + [o[0] for o in p.outcomes]
            if not times:
                continue
            begin = min(times)
            reach = max(reach_s(scene["links"].get(p.src), p.size, self.extent_m) for _, scene in self.scenes)
            finish = max(max(p.txs) + reach if p.txs else begin, max((o[0] for o in p.outcomes), default=begin))
            finish = min(finish, begin + 2 * MAX_FLIGHT_S)
            for bucket in range(math.floor(begin / BUCKET_S), math.floor(finish / BUCKET_S) + 1):
                self.buckets[bucket].append(index)
            self.end = max(self.end, max(times))
        for table in (*self.link_times.values(), *self.flow_times.values(), *self.causes.values()):
            for times in table.values():
                times.sort()
        for errors in self.errors.values():
            errors.sort(key=lambda e: e[0])

    # -- the picture at t -------------------------------------------------------------------------

    def scene_at(self, t: float) -> dict[str, Any]:
        i = bisect_right(self._scene_times, t) - 1
        return self.scenes[max(0, i)][1]

    def linger(self, speed: float) -> float:
        return min(MAX_LINGER_S, max(LINGER_S, LINGER_S * speed))

    def state(self, t: float, speed: float = 1.0, playing: bool = False, floor: float = 0.0) -> dict[str, Any]:
        """The page's STATE at model time ``t`` (played at ``speed``× when ``playing``; ``floor``: the model
        seconds between two pictures, in which every transmission is sent whatever its wave's length)."""
        t = min(max(t, self.start), self.end)
        scene = self.scene_at(t)
        linger = self.linger(speed)
        return {"class": "STATE", "t": round(t, 6), "rate": speed if playing else 0.0, "playing": playing,
                "speed": speed, "start": self.start, "end": round(self.end, 6), "linger_s": linger,
                "vehicles": self._vehicles(scene, t), "links": self._links(scene, t), "hosts": self._hosts(scene, t),
                "frames": self._frames(scene, t, linger, floor), "flows": self._flows(t)}

    def _frames(self, scene: dict, t: float, linger: float, floor: float = 0.0) -> list[dict]:
        seen: set[int] = set()
        chosen = []
        for bucket in range(math.floor((t - max(linger, floor)) / BUCKET_S), math.floor(t / BUCKET_S) + 1):
            for index in self.buckets.get(bucket, ()):
                if index not in seen:
                    seen.add(index)
                    chosen.append(index)
        out = []
        links = scene["links"]
        for index in sorted(chosen, reverse=True):
            p = self.packets[index]
            pkt = p.pkt if p.kind == "data" else f"{p.kind}:{p.pkt}"
            view = frame_view(pkt, p.src, p.dst, p.size, p.txs, p.outcomes, t,
                              reach_s(links.get(p.src), p.size, self.extent_m), linger, p.kind, floor)
            if view is not None:
                out.append(view)
        out.sort(key=lambda f: -(f["tx"] if f["tx"] is not None else f["out"][-1][1]))
        return out[:MAX_FRAMES]

    def _vehicles(self, scene: dict, t: float) -> list[dict]:
        out = []
        for name, vehicle in scene["vehicles"].items():
            times, spots = self.poses.get(name, ((), ()))
            position, age = None, None
            i = bisect_right(times, t)
            if i > 0:
                position, age = spots[i - 1], t - times[i - 1]
                if i < len(times) and position is not None and spots[i] is not None and times[i] > times[i - 1]:
                    w = (t - times[i - 1]) / (times[i] - times[i - 1])
                    position = [a + (b - a) * w for a, b in zip(position, spots[i])]
            elif times:  # before its first sample: where it starts
                position = spots[0]
            lost = i > 0 and spots[i - 1] is None  # the daemon sampled no position: a stale live pose dropped
            out.append({"name": name, "source": vehicle["source"],
                        "position": None if position is None else [round(c, 4) for c in position],
                        "age_s": None if age is None else round(age, 3), "stale": "stale" if lost else None})
        return out

    def _links(self, scene: dict, t: float) -> list[dict]:
        out = []
        for link_id, link in scene["links"].items():
            times = self.link_times.get(link_id, {})
            fifo_times, fifo_levels = self.fifo.get(link_id, ((), ()))
            i = bisect_right(fifo_times, t)
            errors = self.errors.get(link_id, [])
            j = bisect_right(errors, (t, "\U0010ffff"))
            out.append({"id": link_id, "backend": link["backend"], "kind": link["kind"], "state": "up",
                        "ready": None, "fifo_bytes": fifo_levels[i - 1] if i else 0,
                        **{key: bisect_right(times.get(key, ()), t) for key in ("tx", "rx", "drops", "lost")},
                        "causes": {cause: n for cause, stamps in sorted(self.causes.get(link_id, {}).items())
                                   if (n := bisect_right(stamps, t))},
                        "errors": [[round(e[0], 3), e[1], e[2]] for e in errors[max(0, j - ERRORS_KEPT):j]]})
        return out

    def _hosts(self, scene: dict, t: float) -> list[dict]:
        out = []
        for host in sorted(set(scene["hosts"]) | set(self.hosts)):
            changes = self.hosts.get(host, [])
            i = bisect_right(changes, (t, "\U0010ffff"))
            out.append({"host": host, "state": changes[i - 1][1] if i else "up"})
        return out

    def _flows(self, t: float) -> list[dict]:
        out = []
        for (src, dst), times in sorted(self.flow_times.items()):
            lost = {key[5:]: bisect_right(values, t) for key, values in sorted(times.items()) if key.startswith("lost:")}
            out.append({"src": src, "dst": dst, "sent": bisect_right(times.get("sent", ()), t),
                        "received": bisect_right(times.get("received", ()), t),
                        "lost": {cause: n for cause, n in lost.items() if n}})
        return out


def _sorted_pairs(points: list[tuple[float, Any]]) -> tuple[list[float], list[Any]]:
    ordered = sorted(points, key=lambda p: p[0])
    return [p[0] for p in ordered], [p[1] for p in ordered]

