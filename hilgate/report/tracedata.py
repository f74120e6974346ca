"""What ``hilgate report`` reads: the runs of a trace, one run's packets, FIFO levels, poses and backend
periods, and summaries, each checked as :mod:`.tracefile` says (one line naming what is wrong).

A daemon's trace holds the scene it ran (``run`` and ``reload`` lines with ``scene_view``); from
those this reader keeps each link's *backend periods*, so the figures can show when a link was on a
real modem (its frames then carry no packet id and are missing from the flows' timelines).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

from .tracefile import TraceError, count, describe, number, position, printable, read_lines, text

__all__ = ["ReportError", "Packet", "Trace", "Run", "trace_runs", "pick_run", "load_trace", "load_summary",
           "MAX_SUMMARY_BYTES"]

MAX_SUMMARY_BYTES = 64 << 20
FLOW_EVENTS = ("enq", "drop", "tx", "rx", "err")


class ReportError(TraceError):
    pass


@dataclass
class Packet:
    pkt: Any
    src: str
    dst: str
    size: int
    t_enq: float | None = None
    t_tx: list[float] = field(default_factory=list)
    outcomes: list[tuple[float, str, str, str | None]] = field(default_factory=list)  # (t, receiver, ev, cause)
    kind: str = "data"  # a MAC's or a modem's control frame: "ack", "rts", "cts", …


@dataclass
class Trace:
    packets: dict[Any, Packet] = field(default_factory=dict)
    fifo: dict[str, list[tuple[float, int]]] = field(default_factory=lambda: defaultdict(list))
    poses: dict[str, list[tuple[float, list[float] | None]]] = field(default_factory=lambda: defaultdict(list))
    end: float = 0.0
    # link -> [start, end, backend] of each backend period the trace's scene lines name (end None: open)
    backends: dict[str, list[list]] = field(default_factory=lambda: defaultdict(list))
    reloads: list[float] = field(default_factory=list)
    # (t, scene_view) of every run and reload line that carries the scene, in order (``hilgate view``)
    scenes: list[tuple[float, dict]] = field(default_factory=list)
    # (t, host, "up"|"down") of a network of daemons: when this daemon saw another host go or come back
    hosts: list[tuple[float, str, str]] = field(default_factory=list)
    # the MAC's and modems' control frames (acknowledgements, RTS/CTS): drawn by the player on request,
    # never counted in a flow
    control: dict[Any, Packet] = field(default_factory=dict)

    def flows(self) -> list[tuple[str, str]]:
        return sorted({(p.src, p.dst) for p in self.packets.values()})

    def real_periods(self, link: str) -> list[tuple[float, float, str]]:
        """(start, end, backend) of each period ``link`` was on a real modem."""
        return [(start, self.end if end is None else end, backend)
                for start, end, backend in self.backends.get(link, ()) if backend != "sim"]


@dataclass
class Run:
    """One start of the daemon in a trace: the ``run`` header line it wrote, and where its lines are."""

    index: int
    id: str
    start: str
    scene: str
    first_line: int
    last_line: int = 0
    path: str = ""            # the scene file the run line names
    has_view: bool = False    # its run line carries the scene (scene_view)


def trace_runs(path: str) -> list[Run]:
    """The runs in a trace file (the daemon appends one per start).  A trace without any header
    (``hilgate sim``, or an older daemon) is one run.  Only lines that may be ``run`` lines are parsed
    here; what is wrong elsewhere is found when the chosen run is read."""
    from .tracefile import _parse, _Refused, raw_lines

    runs: list[Run] = []
    number_ = 0
    before = False  # lines before the first header: a trace that logrotate cut in the middle of a run
    for number_, raw, cut in raw_lines(path, ReportError):
        if b'"ev": "run"' not in raw:
            before = before or (not runs and bool(raw.strip()))
            continue
        try:
            event = _parse(raw)
        except _Refused as exc:
            if not cut:  # (the last line, cut short by a SIGKILL, is no run line)
                raise ReportError(f"{path}:{number_}: {exc}") from None
            before = before or not runs
            continue
        if not isinstance(event, dict) or event.get("ev") != "run":
            before = before or not runs
            continue
        if not runs and before:
            runs.append(Run(1, "(before the first run line)", "?", "?", 1, number_ - 1))
        if runs:
            runs[-1].last_line = number_ - 1
        scene_path = event.get("path")
        runs.append(Run(len(runs) + 1, _label(event.get("run")), _label(event.get("start")),
                        _label(event.get("scene")), number_, path=scene_path if isinstance(scene_path, str) else "",
                        has_view="scene_view" in event))
    if not runs:
        return [Run(1, "", "", "", 1, number_)]
    runs[-1].last_line = number_
    return runs


def _label(value: Any) -> str:
    return printable(value) if isinstance(value, str) else "?" if value is None else describe(value)


def pick_run(runs: list[Run], wanted: str | None) -> Run:
    """``wanted``: a run id (or its start), a number (1 is the first, -1 the last), or None (the last)."""
    if wanted is None:
        return runs[-1]
    for run in runs:
        if wanted and (run.id == wanted or run.id.startswith(wanted)):
            return run
    try:
        number_ = int(wanted)
        return runs[number_ - 1] if number_ > 0 else runs[number_]
    except (ValueError, IndexError):
        listing = ", ".join(f"{r.index}: {r.id} ({r.start})" for r in runs)
        raise ReportError(f"no run {wanted!r} in the trace; runs: {listing}") from None


def _backends_of(view: Any, where: str) -> dict[str, str]:
    links = view.get("links") if isinstance(view, dict) else None
    if not isinstance(links, dict):
        raise ReportError(f"{where}: scene_view must be an object with the scene's links, not {describe(view)}")
    out = {}
    for name, link in links.items():
        if not isinstance(link, dict):
            raise ReportError(f"{where}: scene_view link {describe(name)} must be an object, not {describe(link)}")
        out[name] = text(link, "backend", f"{where}: scene_view link {describe(name)}")
    return out


def _hashable(value: Any, name: str, where: str) -> Any:
    if isinstance(value, (dict, list)) or value is None:
        raise ReportError(f"{where}: {name!r} must be a frame id, not {describe(value)}")
    if isinstance(value, float) and not math.isfinite(value):  # (the reader refuses these already)
        raise ReportError(f"{where}: {name!r} must be a frame id, not {describe(value)}")
    return value


def load_trace(path: str, window: tuple[float, float] | None = None, run: Run | None = None) -> Trace:
    """Read a trace; with ``window`` only the events from ``window[0]`` to ``window[1]`` seconds, with
    ``run`` only that run's lines (packet ids and times start again at every run).  An unfinished
    last line (the daemon was killed while writing it) is skipped."""
    trace = Trace()
    first, last = (run.first_line, run.last_line) if run is not None else (1, None)
    current: dict[str, str] = {}
    try:
        for line, event in read_lines(path, first, last):
            where = f"{path}:{line}"
            ev = event.get("ev")
            if ev in ("run", "reload"):
                t = number(event, "t", where, 0.0)
                if ev == "run":
                    for periods in trace.backends.values():  # (a headless start: a new run begins)
                        if periods and periods[-1][1] is None:
                            periods[-1][1] = t
                    current = {}
                else:
                    trace.reloads.append(t)
                if "scene_view" in event:
                    current = _periods(trace, current, _backends_of(event["scene_view"], where), t)
                    trace.scenes.append((t, event["scene_view"]))
                continue
            if ev == "host":
                t = number(event, "t", where)
                state = text(event, "state", where)
                if state not in ("up", "down"):
                    raise ReportError(f"{where}: 'state' must be \"up\" or \"down\", not {describe(state)}")
                if window is None or window[0] <= t <= window[1]:
                    trace.hosts.append((t, text(event, "host", where), state))
                continue
            if ev == "pose":
                t = number(event, "t", where)
                vehicle = text(event, "vehicle", where)
                spot = position(event, "position", where)
                if window is None or window[0] <= t <= window[1]:
                    trace.poses[vehicle].append((t, spot))
                    trace.end = max(trace.end, t)
                continue
            if ev not in FLOW_EVENTS or "pkt" not in event:
                continue  # driver and GLI events: not part of a flow's story
            kind = event.get("kind")
            if kind is not None and not isinstance(kind, str):
                raise ReportError(f"{where}: 'kind' must be a text, not {describe(kind)}")
            packets = trace.control if kind else trace.packets  # control frames: not a flow's either
            t = number(event, "t", where)
            if window is not None and not window[0] <= t <= window[1]:
                continue
            trace.end = max(trace.end, t)
            pkt = _hashable(event["pkt"], "pkt", where)
            link = text(event, "link", where)
            packet = packets.get(pkt)
            if packet is None:
                packet = packets[pkt] = Packet(pkt, text(event, "src", where), text(event, "dst", where),
                                               count(event, "size", where), kind=kind or "data")
            if "fifo_bytes" in event and ev in ("enq", "drop", "tx") and not kind:
                trace.fifo[link].append((t, count(event, "fifo_bytes", where)))
            cause = event.get("cause")
            if cause is not None and not isinstance(cause, str):
                raise ReportError(f"{where}: 'cause' must be a text, not {describe(cause)}")
            if ev == "enq":
                packet.t_enq = t
            elif ev == "drop":
                packet.t_enq = t
                packet.outcomes.append((t, link, "drop", cause))
            elif ev == "tx":
                packet.t_tx.append(t)
            else:
                packet.outcomes.append((t, link, ev, cause))
    except ReportError:
        raise
    except TraceError as exc:
        raise ReportError(str(exc)) from None
    return trace


def _periods(trace: Trace, before: dict[str, str], after: dict[str, str], t: float) -> dict[str, str]:
    for link in before.keys() | after.keys():
        if before.get(link) == after.get(link):
            continue
        periods = trace.backends[link]
        if periods and periods[-1][1] is None:
            periods[-1][1] = t
        if link in after:
            periods.append([t, None, after[link]])
    return after


def _strict_constant(literal: str) -> float:
    raise ValueError(f"{literal} is not a number a summary may hold")


def load_summary(path: str) -> dict[str, Any]:
    """A ``--summary`` file, checked as far as ``report`` uses it (its flows and their figures)."""
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_SUMMARY_BYTES + 1)
    except OSError as exc:
        raise ReportError(f"cannot read summary {path}: {exc.strerror}") from None
    if len(data) > MAX_SUMMARY_BYTES:
        raise ReportError(f"cannot read summary {path}: longer than {MAX_SUMMARY_BYTES} bytes")
    try:
        summary = json.loads(data.decode("utf-8"), parse_constant=_strict_constant)
    except RecursionError:
        raise ReportError(f"cannot read summary {path}: nested too deeply") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise ReportError(f"cannot read summary {path}: {str(exc)[:120]}") from None
    flows = summary.get("flows") if isinstance(summary, dict) else None
    if not isinstance(flows, list):
        raise ReportError(f"summary {path}: not a hilgate summary (an object with a list of flows)")
    for i, flow in enumerate(flows):
        where = f"summary {path}: flows[{i}]"
        if not isinstance(flow, dict):
            raise ReportError(f"{where} must be an object, not {describe(flow)}")
        for name in ("from", "to"):
            text(flow, name, where)
        for name, value in flow.items():
            if name in ("offered", "rx_packets", "throughput_Bps", "efficiency", "delay_mean_s", "jitter_s") \
                    and value is not None:
                number(flow, name, where)
    return summary
