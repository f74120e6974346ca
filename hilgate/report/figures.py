"""``hilgate report TRACE [SUMMARY…] --out DIR``: the pictures of a run, and CSV tables.

From a trace: the distance between vehicles over time (from the trace's pose samples); per flow, a
timeline of packets sent, received and lost, coloured by cause; each link's transmit FIFO over time;
the end-to-end delay over time.  From several summaries (one per MAC protocol, say): grouped bars of
throughput, efficiency, delay and jitter per flow.  An ``index.html`` shows them all; ``--csv`` writes
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
                 "closed": "#7f7f7f"}
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


def figures(trace: Trace, summaries: dict[str, dict], vehicles: list[str], out: str,
            title: str = "") -> list[tuple[str, str]]:
    """Write the PNGs; returns (file name, caption) pairs."""
    plt = _pyplot()
    written: list[tuple[str, str]] = []

    def save(fig, name: str, caption: str) -> None:
        fig.tight_layout()
        fig.savefig(os.path.join(out, name), dpi=110)
        plt.close(fig)
        written.append((name, caption))

    pairs = distances(trace, vehicles)
    if pairs:
        fig, ax = plt.subplots(figsize=(9, 3.5))
        for (a, b), points in pairs.items():
            ax.plot([t for t, _ in points], [d for _, d in points], label=f"{a} – {b}")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("distance (m)")
        ax.legend(loc="best", fontsize="small")
        ax.grid(alpha=0.3)
        save(fig, "distance.png", "Distance between vehicles")

    flows = trace.flows()
    if flows:
        fig, axes = plt.subplots(len(flows), 1, figsize=(10.5, 1.6 + 1.3 * len(flows)), squeeze=False, sharex=True)
        for ax, flow in zip(axes[:, 0], flows):
            packets = [p for p in trace.packets.values() if (p.src, p.dst) == flow]
            sent = [t for p in packets for t in p.t_tx]
            ax.scatter(sent, [2] * len(sent), marker="|", s=40, color="#555555", label="sent")
            received = [t for p in packets for t, _, ev, _ in p.outcomes if ev == "rx"]
            ax.scatter(received, [1] * len(received), marker="|", s=40, color="#2ca02c", label="received")
            for cause, colour in CAUSE_COLOURS.items():
                lost = [t for p in packets for t, _, ev, c in p.outcomes if ev in ("err", "drop") and c == cause]
                if lost:
                    ax.scatter(lost, [0] * len(lost), marker="x", s=18, color=colour, label=f"lost: {cause}")
            ax.set_yticks([0, 1, 2], ["lost", "rx", "tx"])
            ax.set_ylim(-0.6, 2.6)
            ax.set_title(f"{flow[0]} → {flow[1]}", fontsize="small", loc="left")
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="x-small")
            ax.grid(axis="x", alpha=0.3)
        axes[-1, 0].set_xlabel("time (s)")
        save(fig, "timeline.png", "Packets of each flow: sent, received, and lost by cause")

        fig, ax = plt.subplots(figsize=(9, 3.5))
        for flow in flows:
            points = delays(trace, flow)
            if points:
                ax.plot([t for t, _ in points], [d for _, d in points], ".", markersize=3, label=f"{flow[0]} → {flow[1]}")
        ax.set_xlabel("time of delivery (s)")
        ax.set_ylabel("end-to-end delay (s)")
        ax.legend(loc="best", fontsize="small")
        ax.grid(alpha=0.3)
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
        save(fig, "fifo.png", "Transmit FIFO occupancy of each link")

    if summaries:
        metrics = [("throughput_Bps", "throughput (B/s)"), ("efficiency", "efficiency"),
                   ("delay_mean_s", "mean delay (s)"), ("jitter_s", "jitter (s)")]
        names = list(summaries)
        flow_keys = list(dict.fromkeys(f"{f['from']} → {f['to']}" for s in summaries.values() for f in s["flows"]))
        fig, axes = plt.subplots(len(metrics), 1, figsize=(max(9, 1.2 * len(flow_keys) * len(names) / 2), 11),
                                 squeeze=False)
        width = 0.8 / len(names)
        for ax, (key, label) in zip(axes[:, 0], metrics):
            for i, name in enumerate(names):
                values = {f"{f['from']} → {f['to']}": f.get(key) for f in summaries[name]["flows"]}
                ax.bar([j + i * width for j in range(len(flow_keys))],
                       [values.get(k) or 0.0 for k in flow_keys], width, label=name)
            ax.set_ylabel(label)
            ax.set_xticks([j + width * (len(names) - 1) / 2 for j in range(len(flow_keys))], flow_keys,
                          rotation=20, ha="right", fontsize="x-small")
            ax.grid(axis="y", alpha=0.3)
        axes[0, 0].legend(loc="best", fontsize="small")
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
           window: tuple[float, float] | None = None, run: Run | None = None) -> list[str]:
    """Everything ``hilgate report`` writes; returns the paths."""
    trace = load_trace(trace_path, window, run)
    summaries = {os.path.splitext(os.path.basename(p))[0]: load_summary(p) for p in summary_paths}
    chosen = vehicles or sorted(trace.poses)[:4]
    os.makedirs(out, exist_ok=True)
    tables = write_csv(trace, summaries, chosen, out) if csv_tables else []
    title = title or f"hilgate report: {os.path.basename(trace_path)}"
    try:
        written = figures(trace, summaries, chosen, out, title)
    except ReportError:
        if csv_tables:
            write_index(out, [], tables, title)
        raise
    index = write_index(out, written, tables, title)
    return [os.path.join(out, name) for name, _ in written] + tables + [index]
