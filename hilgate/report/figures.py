"""``hilgate report TRACE [SUMMARY…] --out DIR``: the pictures of a run, and CSV tables.

From a trace: the distance between vehicles over time (from the trace's pose samples); per flow, a
timeline of packets sent, received and lost, coloured by cause; each link's transmit FIFO over time;
the end-to-end delay over time.  From several summaries (one per MAC protocol, say): grouped bars of
throughput, efficiency, delay and jitter per flow.  Made to go in a paper: series that coincide get
their own line styles and the caption says so; a value axis spanning more than 100× is logarithmic;
timelines too dense for marks are counted per window; plain tick values, delays in ms below a second;
one colour per loss cause everywhere; every caption says what produced the figure; ``--format
svg|pdf`` adds vector files.  An ``index.html`` shows them all; ``--csv`` writes
the tables behind them for people who plot elsewhere.  matplotlib is an optional extra
(``pip install 'hilgate[report]'``); without it the command says so and stops.
"""

from __future__ import annotations

import csv
import html
import itertools
import json
import math
import os
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

CAUSE_COLOURS = {"prop": "#e69f00", "col": "#d62728", "mult": "#9467bd", "fifo": "#222222", "range": "#1f77b4",
                 "closed": "#7f7f7f", "band": "#17becf", "modulation": "#bcbd22"}
MISSING_MATPLOTLIB = ("hilgate report needs matplotlib, an optional extra: pip install 'hilgate[report]' "
                      "(or pip install matplotlib); --csv tables need nothing more")


class ReportError(RuntimeError):
    pass


@dataclass
class Packet:
    pkt: int
    src: str
    dst: str
    size: int
    t_enq: float | None = None
    t_tx: list[float] = field(default_factory=list)
    outcomes: list[tuple[float, str, str, str | None]] = field(default_factory=list)  # (t, receiver, ev, cause)


@dataclass
class Trace:
    packets: dict[int, Packet] = field(default_factory=dict)
    fifo: dict[str, list[tuple[float, int]]] = field(default_factory=lambda: defaultdict(list))
    poses: dict[str, list[tuple[float, list[float] | None]]] = field(default_factory=lambda: defaultdict(list))
    end: float = 0.0

    def flows(self) -> list[tuple[str, str]]:
        return sorted({(p.src, p.dst) for p in self.packets.values()})


@dataclass
class Run:
    """One start of the daemon in a trace: the ``run`` header line it wrote, and where its lines are."""

    index: int
    id: str
    start: str
    scene: str
    first_line: int
    last_line: int = 0


def trace_runs(path: str) -> list[Run]:
    """The runs in a trace file (the daemon appends one per start).  A trace without any header
    (``hilgate sim``, or an older daemon) is one run."""
    runs: list[Run] = []
    try:
        handle = open(path, encoding="utf-8")
    except OSError as exc:
        raise ReportError(f"cannot read trace {path}: {exc.strerror}") from None
    number = 0
    before = False  # lines before the first header: a trace that logrotate cut in the middle of a run
    with handle:
        for number, line in enumerate(handle, 1):
            if '"ev": "run"' not in line:
                before = before or (not runs and bool(line.strip()))
                continue
            try:
                event = json.loads(line)
            except json.JSONDecodeError:
                continue
            if event.get("ev") == "run":
                if not runs and before:
                    runs.append(Run(1, "(before the first run line)", "?", "?", 1, number - 1))
                if runs:
                    runs[-1].last_line = number - 1
                runs.append(Run(len(runs) + 1, str(event.get("run", "?")), str(event.get("start", "?")),
                                str(event.get("scene", "?")), number))
    if not runs:
        return [Run(1, "", "", "", 1, number)]
    runs[-1].last_line = number
    return runs


def pick_run(runs: list[Run], wanted: str | None) -> Run:
    """``wanted``: a run id (or its start), a number (1 is the first, -1 the last), or None (the last)."""
    if wanted is None:
        return runs[-1]
    for run in runs:
        if wanted and (run.id == wanted or run.id.startswith(wanted)):
            return run
    try:
        number = int(wanted)
        return runs[number - 1] if number > 0 else runs[number]
    except (ValueError, IndexError):
        listing = ", ".join(f"{r.index}: {r.id} ({r.start})" for r in runs)
        raise ReportError(f"no run {wanted!r} in the trace; runs: {listing}") from None


def load_trace(path: str, window: tuple[float, float] | None = None, run: Run | None = None) -> Trace:
    """Read a trace; with ``window`` only the events from ``window[0]`` to ``window[1]`` seconds, with
    ``run`` only that run's lines (packet ids and times start again at every run).  An unfinished
    last line (the daemon was killed while writing it) is skipped."""
    trace = Trace()
    try:
        handle = open(path, encoding="utf-8")
    except OSError as exc:
        raise ReportError(f"cannot read trace {path}: {exc.strerror}") from None
    with handle:
        lines = list(enumerate(handle, 1))
    for number, line in lines:
        if run is not None and not run.first_line <= number <= run.last_line:
            continue
        finished = line.endswith("\n")
        line = line.strip()
        if not line:
            continue
        try:
            event = json.loads(line)
        except json.JSONDecodeError:
            if number == len(lines) and not finished:
                continue  # cut short by a SIGKILL
            raise ReportError(f"{path}:{number}: not a JSON line") from None
        t = float(event.get("t", 0.0))
        if window is not None and not window[0] <= t <= window[1]:
            continue
        trace.end = max(trace.end, t)
        ev = event.get("ev")
        if ev == "run":
            continue
        if ev == "pose":
            trace.poses[event["vehicle"]].append((t, event.get("position")))
            continue
        if "pkt" not in event or event.get("kind") or ev not in ("enq", "drop", "tx", "rx", "err"):
            continue  # MAC control frames, driver and GLI events: not part of a flow's story
        packet = trace.packets.get(event["pkt"])
        if packet is None:
            packet = trace.packets[event["pkt"]] = Packet(event["pkt"], event["src"], event["dst"], event["size"])
        if "fifo_bytes" in event and ev in ("enq", "drop", "tx"):
            trace.fifo[event["link"]].append((t, event["fifo_bytes"]))
        if ev == "enq":
            packet.t_enq = t
        elif ev == "drop":
            packet.t_enq = t
            packet.outcomes.append((t, event["link"], "drop", event.get("cause")))
        elif ev == "tx":
            packet.t_tx.append(t)
        else:
            packet.outcomes.append((t, event["link"], ev, event.get("cause")))
    return trace


def load_summary(path: str) -> dict[str, Any]:
    try:
        with open(path, encoding="utf-8") as handle:
            return json.load(handle)
    except (OSError, json.JSONDecodeError) as exc:
        raise ReportError(f"cannot read summary {path}: {exc}") from None


# -- tables ---------------------------------------------------------------------------------------


def distances(trace: Trace, vehicles: list[str]) -> dict[tuple[str, str], list[tuple[float, float]]]:
    series = {}
    for a, b in itertools.combinations(vehicles, 2):
        pa, pb = dict(trace.poses.get(a, [])), dict(trace.poses.get(b, []))
        series[(a, b)] = [(t, math.dist(pa[t], pb[t])) for t in sorted(pa) if t in pb and pa[t] and pb[t]]
    return series


def delays(trace: Trace, flow: tuple[str, str]) -> list[tuple[float, float]]:
    points = []
    for packet in trace.packets.values():
        if (packet.src, packet.dst) == flow and packet.t_enq is not None:
            points += [(t, t - packet.t_enq) for t, _, ev, _ in packet.outcomes if ev == "rx"]
    return sorted(points)


def write_csv(trace: Trace, summaries: dict[str, dict], vehicles: list[str], out: str) -> list[str]:
    files = []

    def table(name: str, header: list[str], rows) -> None:
        path = os.path.join(out, name)
        with open(path, "w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle)
            writer.writerow(header)
            writer.writerows(rows)
        files.append(path)

    table("packets.csv", ["pkt", "src", "dst", "size", "t_enq", "t_tx", "receiver", "t_outcome", "outcome", "cause",
                          "delay_s"],
          ([p.pkt, p.src, p.dst, p.size, p.t_enq, p.t_tx[0] if p.t_tx else "", receiver, t, ev, cause or "",
            t - p.t_enq if ev == "rx" and p.t_enq is not None else ""]
           for p in sorted(trace.packets.values(), key=lambda p: p.pkt) for t, receiver, ev, cause in p.outcomes))
    table("fifo.csv", ["t", "link", "fifo_bytes"],
          ([t, link, size] for link, points in sorted(trace.fifo.items()) for t, size in points))
    table("distances.csv", ["t", "a", "b", "distance_m"],
          ([t, a, b, d] for (a, b), points in distances(trace, vehicles).items() for t, d in points))
    if summaries:
        keys = ["offered", "rx_packets", "throughput_Bps", "efficiency", "delay_mean_s", "jitter_s"]
        table("summaries.csv", ["summary", "from", "to", *keys],
              ([name, f["from"], f["to"], *(f.get(k) for k in keys)]
               for name, s in summaries.items() for f in s["flows"]))
    return files


# -- figures --------------------------------------------------------------------------------------


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise ReportError(MISSING_MATPLOTLIB) from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


LOG_SPAN = 100.0
"""A value axis spanning more than this factor is drawn on a log scale (one series would hide the rest)."""

DENSE = 300
"""More marks than this on one flow's timeline would render as a solid band: they are counted per window."""

STYLES = ["-", "--", ":", "-."]
MARKERS = ["", "o", "s", "^", "v", "D"]


def coinciding(series: dict[str, list]) -> list[list[str]]:
    """Groups (two or more) of series whose points are the same: drawn one over the other, they would
    show as one line."""
    groups: dict[str, list[str]] = {}
    for name, points in series.items():
        groups.setdefault(json.dumps(points, sort_keys=True, default=str), []).append(name)
    return [names for names in groups.values() if len(names) > 1]


def log_scale_needed(values: list[float]) -> bool:
    positive = [v for v in values if v is not None and v > 0]
    return bool(positive) and max(positive) / min(positive) > LOG_SPAN


def _plain(ax) -> None:
    """Plain tick values (no ``1e−13+8.8888933e−2`` offsets) on linear axes."""
    for axis, scale in ((ax.xaxis, ax.get_xscale()), (ax.yaxis, ax.get_yscale())):
        formatter = axis.get_major_formatter()
        if scale == "linear" and hasattr(formatter, "set_useOffset"):  # (not the tick labels a caller named)
            formatter.set_useOffset(False)
            formatter.set_scientific(False)


def _seconds_or_ms(values: list[float]) -> tuple[float, str]:
    """Delays below a second read better in milliseconds."""
    return (1000.0, "ms") if values and max(values) < 1.0 else (1.0, "s")


def figures(trace: Trace, summaries: dict[str, dict], vehicles: list[str], out: str,
            title: str = "", formats: tuple[str, ...] = ("png",), subtitle: str = "",
            inspect: dict[str, dict] | None = None) -> list[tuple[str, str]]:
    """Write the figures (PNG, and SVG/PDF when asked); returns (file name, caption) pairs.  Each
    caption says what produced the figure (``subtitle``: scene, seed, window) and which series
    coincide.  ``inspect`` collects what was drawn, figure by figure (scales, series and their styles),
    for tests that check a figure from its data."""
    plt = _pyplot()
    written: list[tuple[str, str]] = []
    inspect = inspect if inspect is not None else {}

    def save(fig, name: str, caption: str) -> None:
        fig.tight_layout()
        stem = os.path.splitext(name)[0]
        for fmt in formats:
            fig.savefig(os.path.join(out, f"{stem}.{fmt}"), dpi=110)
        plt.close(fig)
        written.append((f"{stem}.{formats[0]}", caption + (f" ({subtitle})" if subtitle else "")))

    pairs = distances(trace, vehicles)
    if pairs:
        fig, ax = plt.subplots(figsize=(9, 3.5))
        series = {f"{a} – {b}": points for (a, b), points in pairs.items()}
        together = coinciding(series)
        styles = {}
        for i, (label, points) in enumerate(series.items()):
            style = (STYLES[i % len(STYLES)], MARKERS[(i // len(STYLES)) % len(MARKERS)])
            styles[label] = style
            ax.plot([t for t, _ in points], [d for _, d in points], linestyle=style[0], marker=style[1] or None,
                    markevery=max(1, len(points) // 12), label=label)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("distance (m)")
        _plain(ax)
        ax.legend(loc="best", fontsize="small")
        ax.grid(alpha=0.3)
        inspect["distance"] = {"styles": styles, "coinciding": together}
        note = "".join(f"; {' and '.join(group)} coincide" for group in together)
        save(fig, "distance.png", "Distance between vehicles" + note)

    flows = trace.flows()
    if flows:
        fig, axes = plt.subplots(len(flows), 1, figsize=(10.5, 1.6 + 1.3 * len(flows)), squeeze=False, sharex=True)
        aggregated = []
        for ax, flow in zip(axes[:, 0], flows):
            packets = [p for p in trace.packets.values() if (p.src, p.dst) == flow]
            sent = [t for p in packets for t in p.t_tx]
            received = [t for p in packets for t, _, ev, _ in p.outcomes if ev == "rx"]
            lost_by_cause = {cause: [t for p in packets for t, _, ev, c in p.outcomes
                                     if ev in ("err", "drop") and c == cause] for cause in CAUSE_COLOURS}
            if len(sent) > DENSE:  # a solid band as marks: rates per window instead
                aggregated.append(f"{flow[0]} → {flow[1]}")
                span = max(trace.end, max(sent)) or 1.0
                width = max(1.0, span / 120)
                edges = [i * width for i in range(int(span / width) + 2)]

                def rate(times: list[float]) -> list[float]:
                    counts = [0] * (len(edges) - 1)
                    for t in times:
                        counts[min(len(counts) - 1, int(t / width))] += 1
                    return [c / width for c in counts]

                ax.step(edges[:-1], rate(sent), where="post", color="#555555", label="sent /s")
                ax.step(edges[:-1], rate(received), where="post", color="#2ca02c", label="received /s")
                for cause, times in lost_by_cause.items():
                    if times:
                        ax.step(edges[:-1], rate(times), where="post", color=CAUSE_COLOURS[cause],
                                label=f"lost: {cause} /s")
                ax.set_ylabel(f"per s ({width:g} s bins)", fontsize="x-small")
            else:
                ax.scatter(sent, [2] * len(sent), marker="|", s=40, color="#555555", label="sent")
                ax.scatter(received, [1] * len(received), marker="|", s=40, color="#2ca02c", label="received")
                for cause, lost in lost_by_cause.items():
                    if lost:
                        ax.scatter(lost, [0] * len(lost), marker="x", s=18, color=CAUSE_COLOURS[cause],
                                   label=f"lost: {cause}")
                ax.set_yticks([0, 1, 2], ["lost", "rx", "tx"])
                ax.set_ylim(-0.6, 2.6)
            _plain(ax)
            ax.set_title(f"{flow[0]} → {flow[1]}", fontsize="small", loc="left")
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="x-small")
            ax.grid(axis="x", alpha=0.3)
        axes[-1, 0].set_xlabel("time (s)")
        inspect["timeline"] = {"aggregated": aggregated}
        note = f"; counted per window for {', '.join(aggregated)}" if aggregated else ""
        save(fig, "timeline.png", "Packets of each flow: sent, received, and lost by cause" + note)

        fig, ax = plt.subplots(figsize=(9, 3.5))
        every = {flow: delays(trace, flow) for flow in flows}
        values = [d for points in every.values() for _, d in points]
        factor, unit = _seconds_or_ms(values)
        for i, (flow, points) in enumerate(every.items()):
            if points:
                ax.plot([t for t, _ in points], [d * factor for _, d in points], MARKERS[1 + i % (len(MARKERS) - 1)],
                        markersize=3, label=f"{flow[0]} → {flow[1]}")
        logarithmic = log_scale_needed(values)
        if logarithmic:
            ax.set_yscale("log")
        ax.set_xlabel("time of delivery (s)")
        ax.set_ylabel(f"end-to-end delay ({unit}{', log scale' if logarithmic else ''})")
        _plain(ax)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize="small")
        ax.grid(alpha=0.3)
        inspect["delay"] = {"yscale": ax.get_yscale(), "unit": unit}
        save(fig, "delay.png", "End-to-end delay of every delivered packet")

    if trace.fifo:
        fig, ax = plt.subplots(figsize=(9, 3.5))
        for link, points in sorted(trace.fifo.items()):
            if any(size for _, size in points):
                ax.step([t for t, _ in points], [size for _, size in points], where="post", label=link)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("transmit FIFO (bytes)")
        ax.legend(loc="best", fontsize="small")
        ax.grid(alpha=0.3)
        _plain(ax)
        save(fig, "fifo.png", "Transmit FIFO occupancy of each link")

    if summaries:
        metrics = [("throughput_Bps", "throughput (B/s)"), ("efficiency", "efficiency"),
                   ("delay_mean_s", "mean delay (s)"), ("jitter_s", "jitter (s)")]
        names = list(summaries)
        flow_keys = list(dict.fromkeys(f"{f['from']} → {f['to']}" for s in summaries.values() for f in s["flows"]))
        fig, axes = plt.subplots(len(metrics), 1, figsize=(max(9, 1.2 * len(flow_keys) * len(names) / 2), 11),
                                 squeeze=False)
        width = 0.8 / len(names)
        scales = {}
        for ax, (key, label) in zip(axes[:, 0], metrics):
            panel = []
            for i, name in enumerate(names):
                values = {f"{f['from']} → {f['to']}": f.get(key) for f in summaries[name]["flows"]}
                heights = [values.get(k) or 0.0 for k in flow_keys]
                panel += heights
                ax.bar([j + i * width for j in range(len(flow_keys))], heights, width, label=name)
            if log_scale_needed(panel):
                ax.set_yscale("log")
                label += ", log scale"
            scales[key] = ax.get_yscale()
            _plain(ax)
            ax.set_ylabel(label)
            ax.set_xticks([j + width * (len(names) - 1) / 2 for j in range(len(flow_keys))], flow_keys,
                          rotation=20, ha="right", fontsize="x-small")
            ax.grid(axis="y", alpha=0.3)
        axes[0, 0].legend(loc="best", fontsize="small")
        inspect["compare"] = {"yscale": scales}
        save(fig, "compare.png", "Per flow, side by side: " + ", ".join(names))
    return written


def write_index(out: str, written: list[tuple[str, str]], tables: list[str], title: str) -> str:
    parts = [f"<!doctype html><meta charset='utf-8'><title>{html.escape(title)}</title>",
             "<style>body{font-family:sans-serif;max-width:1000px;margin:auto}img{max-width:100%}</style>",
             f"<h1>{html.escape(title)}</h1>"]
    for name, caption in written:
        parts.append(f"<figure><img src='{html.escape(name)}' alt='{html.escape(caption)}'>"
                     f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    if tables:
        parts.append("<h2>Tables</h2><ul>" + "".join(
            f"<li><a href='{html.escape(os.path.basename(t))}'>{html.escape(os.path.basename(t))}</a></li>"
            for t in tables) + "</ul>")
    path = os.path.join(out, "index.html")
    with open(path, "w", encoding="utf-8") as handle:
        handle.write("\n".join(parts) + "\n")
    return path


def report(trace_path: str, summary_paths: list[str], out: str, vehicles: list[str] | None = None,
           csv_tables: bool = False, title: str | None = None,
           window: tuple[float, float] | None = None, run: Run | None = None,
           formats: tuple[str, ...] = ("png",)) -> list[str]:
    """Everything ``hilgate report`` writes; returns the paths."""
    if window is not None and not window[0] < window[1]:
        raise ReportError(f"--window {window[0]:g} {window[1]:g} is empty: give START < END in seconds")
    trace = load_trace(trace_path, window, run)
    summaries = {os.path.splitext(os.path.basename(p))[0]: load_summary(p) for p in summary_paths}
    chosen = vehicles or sorted(trace.poses)[:4]
    os.makedirs(out, exist_ok=True)
    tables = write_csv(trace, summaries, chosen, out) if csv_tables else []
    title = title or f"hilgate report: {os.path.basename(trace_path)}"
    produced = [f"trace {os.path.basename(trace_path)}"]
    if run is not None:
        produced.append(f"scene {run.scene}, run {run.id}")
    for name, summary in summaries.items():
        if isinstance(summary, dict) and summary.get("scene") is not None:
            produced.append(f"{name}: scene {summary.get('scene')}, seed {summary.get('seed')}")
    if window is not None:
        produced.append(f"window {window[0]:g}–{window[1]:g} s")
    try:
        written = figures(trace, summaries, chosen, out, title, formats, "; ".join(produced))
    except ReportError:
        if csv_tables:
            write_index(out, [], tables, title)
        raise
    index = write_index(out, written, tables, title)
    return [os.path.join(out, name) for name, _ in written] + tables + [index]
