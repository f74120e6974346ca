"""``hilgate report TRACE [SUMMARY…] --out DIR``: the pictures of a run, and CSV tables.

From a trace: the distance between vehicles over time (from the trace's pose samples); per flow, a
timeline of packets sent, received and lost, coloured by cause, with the periods a link of the flow
was on a real modem shaded; each link's transmit FIFO over time; the end-to-end delay over time.
From several summaries (one per MAC protocol, say): grouped bars of throughput, efficiency, delay
and jitter per flow.

Made to go in a paper, and checked from what was drawn (``inspect``):

- every caption is *in* the figure file's metadata (PNG text, PDF Subject, SVG description), not only in
  ``index.html``, and says what produced the figure; drawn under the plot only when asked
  (``captions``), since a journal sets captions itself;
- PNG at 300 dpi (what journals ask of figures with colour), another resolution when asked; PDF with
  TrueType fonts embedded (journals' PDF checks refuse matplotlib's default Type 3);
- series that coincide get their own line styles and markers, and the caption names them; markers
  are hollow where points of several series overlap (delays);
- a value axis spanning more than 100× is logarithmic, and values a log axis cannot show honestly
  (zero, or below a nanosecond for times: floating-point residues) are not drawn there; the caption
  says how many;
- tick labels never overlap, at any ``--width``: labels that would are thinned or turned;
- the flows' timelines share one time axis, spanning every flow's activity, so that panels compare at a
  glance; timelines too dense for marks are counted per window, the same windows in every panel;
- plain tick values, delays in ms below a second; loss causes in words and one colour each, from the
  table the tables and the web view use too (:mod:`.causes`);
- ``--out`` holds only this run's figures: what an earlier report wrote there is removed first.

One module per figure (``figure_distance``, ``figure_timeline``, ``figure_delay``, ``figure_fifo``,
``figure_compare``) on what they share (:mod:`.figure_kit`, :mod:`.figure_layout`).

matplotlib is an optional extra (``pip install 'hilgate[report]'``); without it the command says so
and stops (``--csv`` tables need nothing more).
"""

from __future__ import annotations

import csv
import html
import math
import os

from .causes import words as cause_words
from .figure_compare import compare_figure
from .figure_delay import delay_figure
from .figure_distance import distance_figure
from .figure_fifo import fifo_figure
from .figure_kit import DPI, WIDTH_IN, FigureWriter, by_flow, check_dpi, distances, pyplot
from .figure_timeline import timeline_figure
from .tracedata import ReportError, Run, Trace, load_summary, load_trace

STEMS = ("distance", "timeline", "delay", "fifo", "compare")
FORMATS = ("png", "svg", "pdf")
TABLES = ("packets.csv", "fifo.csv", "distances.csv", "summaries.csv")


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
                          "delay_s", "cause_in_words"],
          ([p.pkt, p.src, p.dst, p.size, p.t_enq, p.t_tx[0] if p.t_tx else "", receiver, t, ev, cause or "",
            t - p.t_enq if ev == "rx" and p.t_enq is not None else "",
            cause_words(cause) if ev in ("err", "drop") else ""]
           for p in sorted(trace.packets.values(), key=lambda p: str(p.pkt)) for t, receiver, ev, cause in p.outcomes))
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


def figures(trace: Trace, summaries: dict[str, dict], vehicles: list[str], out: str,
            title: str = "", formats: tuple[str, ...] = ("png",), subtitle: str = "",
            inspect: dict[str, dict] | None = None, width: float | None = None, dpi: float = DPI,
            captions: bool = False, files: list[str] | None = None) -> list[tuple[str, str]]:
    """Write the figures (PNG, and SVG/PDF when asked), ``width`` inches wide (default ``WIDTH_IN``,
    and the bars of many flows wider), PNGs at ``dpi``, captions drawn under them when ``captions``;
    returns (file name, caption) pairs, the name in the first format.  ``files`` collects the path of
    every file written (each format: what the command counts).  ``inspect`` collects what was drawn,
    figure by figure (scales, series and their styles, what was left out, whether texts overlap), for
    tests that check a figure from its data."""
    width_given = width is not None
    width = WIDTH_IN if width is None else width
    if not (math.isfinite(width) and 2.0 <= width <= 40.0):
        raise ReportError(f"--width {width:g}: give the figures' width in inches, from 2 to 40")
    check_dpi(dpi)
    plt = pyplot()
    inspect = inspect if inspect is not None else {}
    writer = FigureWriter(plt, out, formats, subtitle, inspect, title or "hilgate report", dpi, captions)
    distance_figure(plt, writer, trace, vehicles, width)
    flows = by_flow(trace)
    if flows:
        timeline_figure(plt, writer, trace, flows, width)
        delay_figure(plt, writer, trace, flows, width)
    if trace.fifo:
        fifo_figure(plt, writer, trace, width)
    if summaries:
        compare_figure(plt, writer, summaries, width, width_given)
    if files is not None:
        files.extend(writer.files)
    return writer.written


def clear_previous(out: str) -> list[str]:
    """Remove what an earlier ``hilgate report`` wrote into ``out`` (its figures, tables and page, by
    name; nothing else), so the folder holds only this run's figures.  Returns what was removed."""
    removed = []
    names = [f"{stem}.{fmt}" for stem in STEMS for fmt in FORMATS] + list(TABLES) + ["index.html"]
    for name in names:
        path = os.path.join(out, name)
        if os.path.islink(path) or os.path.isfile(path):
            os.remove(path)
            removed.append(name)
    return removed


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
           formats: tuple[str, ...] = ("png",), width: float | None = None, dpi: float = DPI,
           captions: bool = False) -> list[str]:
    """Everything ``hilgate report`` writes; returns the paths, every one (each format of each figure)."""
    if window is not None and not window[0] < window[1]:
        raise ReportError(f"--window {window[0]:g} {window[1]:g} is empty: give START < END in seconds")
    if width is not None and not (math.isfinite(width) and 2.0 <= width <= 40.0):
        raise ReportError(f"--width {width:g}: give the figures' width in inches, from 2 to 40")
    check_dpi(dpi)
    trace = load_trace(trace_path, window, run)
    summaries = {os.path.splitext(os.path.basename(p))[0]: load_summary(p) for p in summary_paths}
    chosen = vehicles or sorted(trace.poses)[:4]
    os.makedirs(out, exist_ok=True)
    clear_previous(out)
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
    files: list[str] = []
    try:
        written = figures(trace, summaries, chosen, out, title, formats, "; ".join(produced), width=width, dpi=dpi,
                          captions=captions, files=files)
    except ReportError:
        if csv_tables:
            write_index(out, [], tables, title)
        raise
    index = write_index(out, written, tables, title)
    return files + tables + [index]
