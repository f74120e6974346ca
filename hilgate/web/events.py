"""The event log of a trace, for the player's time axis and its log: reloads and the links they swapped,
hosts lost and back, bursts of losses by cause, vehicles without a pose.

The live page derives the same events from one picture to the next (``static/events.js``); a trace is
indexed once here, so the player can mark every event on its time axis and step from one to the next.
Events carry codes (a cause's ``col``, a link's id), never sentences: the page words them with its one
vocabulary, so the log, the tables and the legend say the same thing.  Sans-I/O.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any, Iterable

__all__ = ["BURST_N", "BURST_GAP_S", "MAX_EVENTS", "bursts", "scene_events", "host_events", "pose_events",
           "trace_events"]

BURST_N = 3
"""Losses of one cause at one link that make a burst worth a line (fewer are the tables' business)."""
BURST_GAP_S = 5.0
"""Model seconds between two losses of one burst; a longer quiet ends it (the page uses the same)."""
MAX_EVENTS = 2000
"""Events a player keeps (the first ones): its axis and log stay readable and its message small."""


def bursts(losses: Iterable[tuple[float, str, str]]) -> list[dict[str, Any]]:
    """``(t, link, cause)`` of every loss → one ``burst`` event per run of at least ``BURST_N`` losses of a
    cause at a link, each within ``BURST_GAP_S`` of the one before, at the run's first loss."""
    by_key: dict[tuple[str, str], list[float]] = defaultdict(list)
    for t, link, cause in losses:
        by_key[(link, cause)].append(t)
    out = []
    for (link, cause), times in by_key.items():
        times.sort()
        start = 0
        for i in range(1, len(times) + 1):
            if i == len(times) or times[i] - times[i - 1] > BURST_GAP_S:
                n = i - start
                if n >= BURST_N:
                    out.append({"t": round(times[start], 6), "level": "warning", "kind": "burst", "link": link,
                                "cause": cause, "n": n, "until": round(times[i - 1], 6)})
                start = i
    return out


def scene_events(scenes: list[tuple[float, dict[str, Any]]]) -> list[dict[str, Any]]:
    """A ``reload`` event for every scene after the first (SCENE messages), with the links whose backend it
    swapped (``[link, before, after]``, a kind and a backend each) and those it added or removed."""
    out = []
    for (_, before), (t, after) in zip(scenes, scenes[1:]):
        old, new = before.get("links", {}), after.get("links", {})
        swaps = [[link, _backend(old[link]), _backend(new[link])] for link in sorted(set(old) & set(new))
                 if _backend(old[link]) != _backend(new[link])]
        out.append({"t": round(t, 6), "level": "warning" if swaps else "info", "kind": "reload",
                    "scene": after.get("name", "?"), "swaps": swaps, "added": sorted(set(new) - set(old)),
                    "removed": sorted(set(old) - set(new))})
    return out


def _backend(link: dict[str, Any]) -> str:
    return "sim" if link.get("kind") == "sim" else f"{link.get('kind')} {link.get('backend')}"


def host_events(hosts: Iterable[tuple[float, str, str]]) -> list[dict[str, Any]]:
    """A host lost (an error: its links are gone) or back."""
    return [{"t": round(t, 6), "level": "error" if state == "down" else "info", "kind": "host", "host": host,
             "state": state} for t, host, state in hosts]


def pose_events(poses: dict[str, tuple[list[float], list[Any]]]) -> list[dict[str, Any]]:
    """A vehicle whose samples lose their position (a stale live pose dropped), and when it has one again."""
    out = []
    for vehicle, (times, spots) in poses.items():
        known = True
        for t, spot in zip(times, spots):
            if (spot is not None) != known:
                known = spot is not None
                out.append({"t": round(t, 6), "level": "info" if known else "warning", "kind": "pose",
                            "vehicle": vehicle, "state": "fresh" if known else "lost"})
    return out


def trace_events(scenes: list[tuple[float, dict[str, Any]]], hosts: Iterable[tuple[float, str, str]],
                 poses: dict[str, tuple[list[float], list[Any]]],
                 losses: Iterable[tuple[float, str, str]]) -> list[dict[str, Any]]:
    """Every event of a trace, in time order (at most ``MAX_EVENTS``)."""
    events = [*scene_events(scenes), *host_events(hosts), *pose_events(poses), *bursts(losses)]
    events.sort(key=lambda e: e["t"])
    return events[:MAX_EVENTS]
