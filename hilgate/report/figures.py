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

matplotlib is an optional extra (``pip install 'hilgate[report]'``); without it the command says so
and stops (``--csv`` tables need nothing more).
"""

from __future__ import annotations

import csv
import html
import itertools
import json
import logging
import math
import os
import textwrap
import warnings
from collections import defaultdict
from typing import Any

from .causes import RECEIVED, legend_order
from .causes import colour as cause_colour
from .causes import words as cause_words
from .tracedata import Packet, ReportError, Run, Trace, load_summary, load_trace

log = logging.getLogger(__name__)

REAL_SHADE = "#9ecae1"
MISSING_MATPLOTLIB = ("hilgate report needs matplotlib, an optional extra: pip install 'hilgate[report]' "
                      "(or pip install matplotlib); --csv tables need nothing more")

STEMS = ("distance", "timeline", "delay", "fifo", "compare")
FORMATS = ("png", "svg", "pdf")
TABLES = ("packets.csv", "fifo.csv", "distances.csv", "summaries.csv")

LOG_SPAN = 100.0
"""A value axis spanning more than this factor is drawn on a log scale (one series would hide the rest)."""

RESIDUE_S = 1e-9
"""Times at or below a nanosecond are floating-point residues of a zero (a delay computed as the
difference of two equal times): never drawn on a log axis, where they would stretch it by decades."""

DENSE = 300
"""More marks than this on one flow's timeline would render as a solid band: they are counted per window."""

MAX_PANELS = 24
"""Flows drawn on the timeline (the busiest ones); the caption names how many more there are."""

MAX_SERIES = 12
"""Series on one axes (links' FIFOs, flows' delays): the busiest ones, the caption says how many more."""

WIDTH_IN = 9.0

DPI = 300.0
"""PNG resolution: journals ask 300 dpi of figures with colour (line art alone: 600 to 1200, on request)."""

DPI_RANGE = (50.0, 1200.0)

MAX_PIXELS = 200e6
"""A PNG larger than this (800 MB while drawn) is refused with the resolution that fits: the tallest
timeline (24 panels, 37 inches) at 1200 dpi would take 2 GB of a lab's PC."""

VECTOR_FONTS = {"pdf.fonttype": 42, "ps.fonttype": 42}
"""TrueType fonts embedded in PDF, not matplotlib's default Type 3, which journals' PDF checks refuse."""

CAPTION_PT = 8.0
MIN_TICK_PT = 6.0

STYLES = ["-", "--", ":", "-."]
MARKERS = ["", "o", "s", "^", "v", "D"]
POINT_MARKERS = ["o", "s", "^", "v", "D", "P", "X", "<", ">", "h"]


# -- tables ---------------------------------------------------------------------------------------


def distances(trace: Trace, vehicles: list[str]) -> dict[tuple[str, str], list[tuple[float, float]]]:
    series = {}
    for a, b in itertools.combinations(vehicles, 2):
        pa, pb = dict(trace.poses.get(a, [])), dict(trace.poses.get(b, []))
        series[(a, b)] = [(t, math.dist(pa[t], pb[t])) for t in sorted(pa) if t in pb and pa[t] and pb[t]]
    return series


def _by_flow(trace: Trace) -> dict[tuple[str, str], list[Packet]]:
    flows: dict[tuple[str, str], list[Packet]] = defaultdict(list)
    for packet in trace.packets.values():
        flows[(packet.src, packet.dst)].append(packet)
    return flows


def delays(trace: Trace, flow: tuple[str, str], packets: list[Packet] | None = None) -> list[tuple[float, float]]:
    points = []
    chosen = packets if packets is not None else [p for p in trace.packets.values() if (p.src, p.dst) == flow]
    for packet in chosen:
        if packet.t_enq is not None:
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


# -- drawing helpers ------------------------------------------------------------------------------


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise ReportError(MISSING_MATPLOTLIB) from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def coinciding(series: dict[str, list]) -> list[list[str]]:
    """Groups (two or more) of series whose points are the same: drawn one over the other, they would
    show as one line."""
    groups: dict[str, list[str]] = {}
    for name, points in series.items():
        groups.setdefault(json.dumps(points, sort_keys=True, default=str), []).append(name)
    return [names for names in groups.values() if len(names) > 1]


def log_scale_needed(values: list[float], residue: float = 0.0) -> bool:
    """Whether the values above ``residue`` span more than ``LOG_SPAN``."""
    positive = [v for v in values if v is not None and v > residue]
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


def _short(label: str, limit: int = 28) -> str:
    """A category label short enough to read under a bar (the full name is in the CSV tables)."""
    if len(label) <= limit:
        return label
    keep = (limit - 1) // 2
    return label[:keep] + "…" + label[-(limit - 1 - keep):]


def _style(i: int) -> tuple[str, str]:
    """A line style and marker per series, different for the first 24."""
    return STYLES[i % len(STYLES)], MARKERS[(i // len(STYLES)) % len(MARKERS)]


def _span(times: list[float]) -> tuple[float, float]:
    """A time axis' range: the activity, with a margin."""
    low, high = min(times), max(times)
    pad = 0.04 * (high - low) if high > low else max(0.5, abs(low) * 1e-6)
    return low - pad, high + pad


LEGEND_PT = 7.0


def _legend(ax, width_in: float, handles: list | None = None, labels: list[str] | None = None,
            columns: int | None = None, chars: int | None = None) -> None:
    """The legend above the axes, in as many columns as fit the figure's width, labels shortened to
    fit (the full names are in the CSV tables): inside the axes it would hide data, beside them it
    would squeeze a narrow figure.  :func:`_fit_legends` narrows it further once laid out."""
    if handles is None or labels is None:
        handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return
    char_pt = LEGEND_PT * 0.62
    room_pt = width_in * 72 * 0.82
    chars = chars or max(10, int((room_pt - 28) / char_pt))
    shown = [_short(label, chars) for label in labels]
    column_pt = max(len(label) for label in shown) * char_pt + 28
    if columns is None:
        columns = max(1, min(len(shown), int(room_pt // column_pt)))
    ax.legend(handles, shown, loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=columns, fontsize=LEGEND_PT,
              frameon=False, borderaxespad=0.0, handlelength=1.6, columnspacing=1.0)
    ax._hilgate_legend = (width_in, handles, labels, columns, chars)


def _fit_legends(fig) -> bool:
    """A legend that runs off the figure takes fewer columns (more rows), then shorter labels, until it
    fits."""
    changed = False
    fig.canvas.draw()
    for ax in fig.axes:
        made = getattr(ax, "_hilgate_legend", None)  # (by name: matplotlib's axes carry our mark)
        while made is not None and ax.get_legend() is not None and not _inside(fig, ax.get_legend()):
            width_in, handles, labels, columns, chars = made
            if columns > 1:
                columns -= 1
            elif chars > 8:
                chars = max(8, chars - 4)
            else:
                break
            _legend(ax, width_in, handles, labels, columns, chars)
            made = ax._hilgate_legend
            changed = True
            fig.canvas.draw()
    return changed


def _overlapping(boxes: list) -> bool:
    for a, b in zip(boxes, boxes[1:]):
        if a.x0 < b.x1 - 1 and b.x0 < a.x1 - 1 and a.y0 < b.y1 - 1 and b.y0 < a.y1 - 1:
            return True
    return False


def _shown_labels(axis) -> list:
    """The tick labels drawn: visible, with text, and at a tick inside the axis' view (matplotlib
    keeps labels for ticks just outside it, which are not drawn)."""
    low, high = sorted(axis.get_view_interval())
    slack = (high - low) * 1e-9
    return [label for loc, label in zip(axis.get_majorticklocs(), axis.get_majorticklabels())
            if label.get_visible() and label.get_text() and low - slack <= loc <= high + slack]


def _tick_boxes(axis, renderer) -> list:
    boxes = [label.get_window_extent(renderer) for label in _shown_labels(axis)]
    return sorted(boxes, key=lambda b: (b.x0, b.y0))


def _clear_corners(ax, renderer) -> bool:
    """An x tick label at the axes' edge may run into the y tick labels beside it: it is hidden."""
    ys = _tick_boxes(ax.yaxis, renderer)
    hidden = False
    for label in _shown_labels(ax.xaxis):
        box = label.get_window_extent(renderer)
        if any(box.x0 < y.x1 - 1 and y.x0 < box.x1 - 1 and box.y0 < y.y1 - 1 and y.y0 < box.y1 - 1 for y in ys):
            label.set_visible(False)
            hidden = True
    return hidden


def _legible(fig) -> tuple[bool, int]:
    """Thin or turn the tick labels of every axis until none overlaps another; returns whether it
    changed any, and how many axes still have overlapping labels (0, unless a figure is absurdly small)."""
    from matplotlib.ticker import FixedLocator, MaxNLocator

    changed, still = False, 0
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for label in axis.get_ticklabels():
                if label.get_fontsize() < MIN_TICK_PT:
                    label.set_fontsize(MIN_TICK_PT)
            tries = 0
            while _overlapping(_tick_boxes(axis, renderer)) and tries < 12:
                tries += 1
                changed = True
                locator = axis.get_major_locator()
                if isinstance(locator, FixedLocator) or axis.get_scale() == "log":
                    labels = _shown_labels(axis)
                    if axis is ax.xaxis and tries == 1:
                        for label in labels:  # named categories: upright first
                            label.set_rotation(90)
                            label.set_horizontalalignment("center")
                    else:
                        for label in labels[1::2]:  # then every other one
                            label.set_visible(False)
                else:
                    count = max(2, len([t for t in axis.get_ticklabels() if t.get_text()]) // 2)
                    axis.set_major_locator(MaxNLocator(nbins=count, min_n_ticks=1))
                fig.canvas.draw()
            still += _overlapping(_tick_boxes(axis, renderer))
        if _clear_corners(ax, renderer):
            changed = True
            fig.canvas.draw()
    return changed, still


def _collisions(fig, caption) -> int:
    """Pairs of texts of different kinds that overlap: tick labels of one axis, axis labels, legends,
    the caption (when drawn)."""
    renderer = fig.canvas.get_renderer()
    groups: list[list] = [[caption.get_window_extent(renderer)]] if caption is not None else []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            groups.append(_tick_boxes(axis, renderer))
            if axis.label.get_text():
                groups.append([axis.label.get_window_extent(renderer)])
        legend = ax.get_legend()
        if legend is not None:
            groups.append([legend.get_window_extent(renderer)])
    hits = 0
    for i, first in enumerate(groups):
        for second in groups[i + 1:]:
            hits += any(a.x0 < b.x1 - 1 and b.x0 < a.x1 - 1 and a.y0 < b.y1 - 1 and b.y0 < a.y1 - 1
                        for a in first for b in second)
    return hits


def _outside(fig) -> int:
    """Texts (tick labels, axis labels, legends) that run off the figure."""
    renderer = fig.canvas.get_renderer()
    count = 0
    for ax in fig.axes:
        texts = _shown_labels(ax.xaxis) + _shown_labels(ax.yaxis) + [ax.xaxis.label, ax.yaxis.label]
        legend = ax.get_legend()
        count += sum(1 for t in texts if t.get_text() and not _inside(fig, t))
        count += legend is not None and not _inside(fig, legend)
    return count


def _caption_lines(caption: str, width_in: float) -> list[str]:
    per_line = max(24, int(width_in * 72 / (CAPTION_PT * 0.62)))
    lines = textwrap.wrap(caption, per_line) or [""]
    if len(lines) > 10:
        lines = lines[:9] + [textwrap.shorten(" ".join(lines[9:]), per_line, placeholder=" …")]
    return lines


def _inside(fig, artist) -> bool:
    renderer = fig.canvas.get_renderer()
    box, frame = artist.get_window_extent(renderer), fig.bbox
    return frame.x0 - 1 <= box.x0 and box.x1 <= frame.x1 + 1 and frame.y0 - 1 <= box.y0 and box.y1 <= frame.y1 + 1


class _Writer:
    """Saves figures with their caption in the files' metadata, and drawn under them when asked."""

    def __init__(self, plt, out: str, formats: tuple[str, ...], subtitle: str, inspect: dict, title: str,
                 dpi: float = DPI, captions: bool = False):
        self.plt, self.out, self.formats, self.subtitle, self.inspect, self.title = \
            plt, out, formats, subtitle, inspect, title
        self.dpi, self.captions = dpi, captions
        self.written: list[tuple[str, str]] = []
        self.files: list[str] = []  # every file saved, each format of each figure

    def save(self, fig, stem: str, caption: str) -> None:
        caption = caption + (f" ({self.subtitle})" if self.subtitle else "")
        text, extra = None, 0.0
        height = fig.get_figheight()
        if self.captions:
            lines = _caption_lines(caption, fig.get_figwidth())
            extra = (len(lines) * CAPTION_PT * 1.32 + 10) / 72
            height += extra
            fig.set_figheight(height)
            text = fig.text(0.012, 4 / 72 / height, "\n".join(lines), fontsize=CAPTION_PT, ha="left", va="bottom",
                            gid="caption")
        with warnings.catch_warnings(record=True) as complaints:
            warnings.simplefilter("always")
            fig.tight_layout(rect=(0, extra / height, 1, 1))
            if _fit_legends(fig) | _legible(fig)[0]:  # what moved takes other room: lay out again, check again
                fig.tight_layout(rect=(0, extra / height, 1, 1))
                _fit_legends(fig)
        overlaps = _legible(fig)[1]
        self.inspect.setdefault(stem, {}).update({
            "overlaps": overlaps, "collisions": _collisions(fig, text), "outside": _outside(fig), "caption": caption,
            "caption_drawn": text is not None, "caption_inside": text is not None and _inside(fig, text),
            "width_in": fig.get_figwidth(), "layout": not any("tight" in str(w.message).lower() for w in complaints)})
        if "png" in self.formats:
            _check_pixels(fig, stem, self.dpi)
        import matplotlib

        with matplotlib.rc_context(VECTOR_FONTS):
            for fmt in self.formats:
                metadata = ({"Title": f"{self.title}: {stem}", "Subject": caption} if fmt == "pdf"
                            else {"Title": f"{self.title}: {stem}", "Description": caption})
                path = os.path.join(self.out, f"{stem}.{fmt}")
                fig.savefig(path, dpi=self.dpi, metadata=metadata)
                self.files.append(path)
                log.debug("wrote %s", path)
        self.plt.close(fig)
        self.written.append((f"{stem}.{self.formats[0]}", caption))


# -- the figures ----------------------------------------------------------------------------------


def check_dpi(dpi: float) -> None:
    if not (math.isfinite(dpi) and DPI_RANGE[0] <= dpi <= DPI_RANGE[1]):
        raise ReportError(f"--dpi {dpi:g}: give the PNGs' resolution in dots per inch, from {DPI_RANGE[0]:g} "
                          f"to {DPI_RANGE[1]:g} (journals ask 300)")


def _check_pixels(fig, stem: str, dpi: float) -> None:
    width_in, height_in = fig.get_figwidth(), fig.get_figheight()
    if width_in * height_in * dpi * dpi > MAX_PIXELS:
        fits = int(math.sqrt(MAX_PIXELS / (width_in * height_in)))
        raise ReportError(f"--dpi {dpi:g}: {stem}.png would be {width_in:.1f} × {height_in:.1f} inches at {dpi:g} dpi, "
                          f"{width_in * height_in * dpi * dpi / 1e6:.0f} million pixels; give --dpi {fits} or less, "
                          f"or a smaller --width")


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
    plt = _pyplot()
    inspect = inspect if inspect is not None else {}
    writer = _Writer(plt, out, formats, subtitle, inspect, title or "hilgate report", dpi, captions)
    _distance_figure(plt, writer, trace, vehicles, width)
    flows = _by_flow(trace)
    if flows:
        _timeline_figure(plt, writer, trace, flows, width)
        _delay_figure(plt, writer, trace, flows, width)
    if trace.fifo:
        _fifo_figure(plt, writer, trace, width)
    if summaries:
        _compare_figure(plt, writer, summaries, width, width_given)
    if files is not None:
        files.extend(writer.files)
    return writer.written


def _distance_figure(plt, writer: _Writer, trace: Trace, vehicles: list[str], width: float) -> None:
    pairs = {pair: points for pair, points in distances(trace, vehicles).items() if points}
    if not pairs:
        return
    fig, ax = plt.subplots(figsize=(width, 3.5))
    series = {f"{a} – {b}": points for (a, b), points in pairs.items()}
    together = coinciding(series)
    styles = {}
    for i, (label, points) in enumerate(series.items()):
        style = _style(i)
        styles[label] = style
        ax.plot([t for t, _ in points], [d for _, d in points], linestyle=style[0], marker=style[1] or None,
                markevery=max(1, len(points) // 12), fillstyle="none", label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance (m)")
    _plain(ax)
    _legend(ax, width)
    ax.grid(alpha=0.3)
    writer.inspect["distance"] = {"styles": styles, "coinciding": together}
    note = "".join(f"; {' and '.join(group)} coincide" for group in together)
    writer.save(fig, "distance", "Distance between vehicles" + note)


def _busiest(flows: dict[tuple[str, str], list[Packet]], limit: int) -> list[tuple[str, str]]:
    ranked = sorted(flows, key=lambda f: (-len(flows[f]), f))[:limit]
    return sorted(ranked)


def _activity(packets: list[Packet]) -> tuple[list[float], list[float], dict[str | None, list[float]], list[float]]:
    """A flow's times: sent, received, lost by cause, and all of them with the enqueues."""
    sent = [t for p in packets for t in p.t_tx]
    received = [t for p in packets for t, _, ev, _ in p.outcomes if ev == "rx"]
    lost_by_cause: dict[str | None, list[float]] = defaultdict(list)
    for p in packets:
        for t, _, ev, cause in p.outcomes:
            if ev in ("err", "drop"):
                lost_by_cause[cause].append(t)
    every = sent + received + [t for times in lost_by_cause.values() for t in times] + \
        [p.t_enq for p in packets if p.t_enq is not None]
    return sent, received, lost_by_cause, every


def _timeline_figure(plt, writer: _Writer, trace: Trace, flows: dict[tuple[str, str], list[Packet]],
                     width: float) -> None:
    """One panel per flow, on one time axis: a reader compares when flows were busy, lost frames or
    were on a real modem by looking down the page, as a journal's figure of stacked panels reads."""
    chosen = _busiest(flows, MAX_PANELS)
    fig, axes = plt.subplots(len(chosen), 1, figsize=(width, 1.0 + 1.45 * len(chosen)), squeeze=False,
                             sharex=True)
    times = {flow: _activity(flows[flow]) for flow in chosen}
    every = [t for flow in chosen for t in times[flow][3]]
    low, high = _span(every) if every else (0.0, 1.0)
    bin_s = (high - low) / 120 if high > low else 1.0  # (the same windows in every dense panel)
    aggregated, shaded = [], {}
    handles: dict[str, Any] = {}
    ranks: dict[str, tuple] = {}  # the legend's order: sent, received, losses as the causes' table lists them
    for ax, flow in zip(axes[:, 0], chosen):
        sent, received, lost_by_cause, _ = times[flow]
        causes = sorted(lost_by_cause, key=legend_order)
        if len(sent) > DENSE:  # a solid band as marks: rates per window instead
            aggregated.append(f"{flow[0]} → {flow[1]}")
            edges = [low + i * bin_s for i in range(121)]

            def rate(moments: list[float]) -> list[float]:
                counts = [0] * 120
                for t in moments:
                    counts[min(119, max(0, int((t - low) / bin_s)))] += 1
                return [c / bin_s for c in counts]

            peak = 0.0
            for label, moments, colour, rank in [("sent /s", sent, "#555555", (0, 0)),
                                                 (f"{RECEIVED.words} /s", received, RECEIVED.colour, (0, 1))] + \
                    [(f"lost: {cause_words(cause)} /s", lost_by_cause[cause], cause_colour(cause),
                      (1, legend_order(cause))) for cause in causes]:
                if moments:
                    values = rate(moments)
                    peak = max(peak, max(values))
                    handles[label] = ax.step(edges[:-1], values, where="post", color=colour, label=label)[0]
                    ranks[label] = rank
            ax.set_ylim(0, peak * 1.45 or 1.0)
            ax.set_ylabel(f"per s ({bin_s:.3g} s bins)", fontsize="x-small")
        else:
            handles["sent"] = ax.scatter(sent, [2] * len(sent), marker="|", s=40, color="#555555", label="sent")
            handles[RECEIVED.words] = ax.scatter(received, [1] * len(received), marker="|", s=40,
                                                 color=RECEIVED.colour, label=RECEIVED.words)
            ranks.update({"sent": (0, 0), RECEIVED.words: (0, 1)})
            for cause in causes:
                label = f"lost: {cause_words(cause)}"
                handles[label] = ax.scatter(lost_by_cause[cause], [0] * len(lost_by_cause[cause]), marker="x", s=18,
                                            color=cause_colour(cause), label=label)
                ranks[label] = (1, legend_order(cause))
            ax.set_yticks([0, 1, 2], ["lost", RECEIVED.words, "sent"])
            ax.set_ylim(-0.6, 3.3)
        periods = []
        for link in dict.fromkeys(flow):
            for start, end, backend in trace.real_periods(link):
                if end >= low and start <= high:
                    periods.append((max(start, low), min(end, high), backend, link))
                    handles["link on a real modem"] = ax.axvspan(max(start, low), min(end, high), color=REAL_SHADE,
                                                                 alpha=0.45, lw=0, zorder=0,
                                                                 label="link on a real modem")
                    ax.text(max(start, low), 0.02, f" {link}: {backend}", transform=ax.get_xaxis_transform(),
                            fontsize="xx-small", va="bottom", ha="left", clip_on=True)
        if periods:
            shaded[f"{flow[0]} → {flow[1]}"] = periods
        _plain(ax)
        ax.text(0.005, 0.97, _short(f"{flow[0]} → {flow[1]}", max(16, int(width * 72 * 0.8 / (8.3 * 0.62)))),
                transform=ax.transAxes, fontsize="small", va="top", ha="left",
                bbox={"facecolor": "white", "alpha": 0.8, "lw": 0, "pad": 1})
        ax.grid(axis="x", alpha=0.3)
    axes[0, 0].set_xlim(low, high)  # (shared: every panel's)
    axes[-1, 0].set_xlabel("time (s)")
    fig.align_ylabels(axes[:, 0])
    labels = sorted(handles, key=lambda label: ranks.get(label, (2,)))
    _legend(axes[0, 0], width, [handles[label] for label in labels], labels)
    writer.inspect["timeline"] = {"aggregated": aggregated, "xlim": (low, high), "real_periods": shaded,
                                  "panels": [f"{a} → {b}" for a, b in chosen]}
    note = f"; counted per {bin_s:.3g} s window for {', '.join(aggregated)}" if aggregated else ""
    if shaded:
        note += ("; shaded: a link of the flow on a real modem (its frames then carry no packet id and are not "
                 "on this timeline)")
    if len(flows) > len(chosen):
        note += f"; the {len(chosen)} busiest of {len(flows)} flows (all are in packets.csv with --csv)"
    writer.save(fig, "timeline", "Packets of each flow: sent, received, and lost by cause; the panels share one "
                                 "time axis" + note)


def _delay_figure(plt, writer: _Writer, trace: Trace, flows: dict[tuple[str, str], list[Packet]],
                  width: float) -> None:
    every = {flow: delays(trace, flow, packets) for flow, packets in flows.items()}
    every = {flow: points for flow, points in every.items() if points}
    chosen = sorted(sorted(every, key=lambda f: (-len(every[f]), f))[:MAX_SERIES])
    values = [d for flow in chosen for _, d in every[flow]]
    logarithmic = log_scale_needed(values, RESIDUE_S)
    shown = [d for d in values if d > RESIDUE_S] if logarithmic else values
    factor, unit = _seconds_or_ms(shown)
    fig, ax = plt.subplots(figsize=(width, 3.5))
    left_out = 0
    series = {}
    for i, flow in enumerate(chosen):
        points = [(t, d) for t, d in every[flow] if not logarithmic or d > RESIDUE_S]
        left_out += len(every[flow]) - len(points)
        series[f"{flow[0]} → {flow[1]}"] = points
        if points:
            ax.plot([t for t, _ in points], [d * factor for _, d in points], linestyle="none",
                    marker=POINT_MARKERS[i % len(POINT_MARKERS)], fillstyle="none", markersize=4, alpha=0.85,
                    label=f"{flow[0]} → {flow[1]}")
    if logarithmic:
        ax.set_yscale("log")
    ax.set_xlabel("time of delivery (s)")
    ax.set_ylabel(f"end-to-end delay ({unit}{', log scale' if logarithmic else ''})")
    _plain(ax)
    _legend(ax, width)
    ax.grid(alpha=0.3)
    together = coinciding(series)
    writer.inspect["delay"] = {"yscale": ax.get_yscale(), "unit": unit, "not_drawn": left_out,
                               "coinciding": together, "series": list(series)}
    note = "".join(f"; {' and '.join(group)} coincide" for group in together)
    if left_out:
        note += f"; {left_out} delays of zero or below 1 ns are not drawn on the log axis"
    if len(every) > len(chosen):
        note += f"; the {len(chosen)} flows with most deliveries of {len(every)}"
    writer.save(fig, "delay", "End-to-end delay of every delivered packet (hollow marks: overlapping ones "
                              "stay visible)" + note)


def _fifo_figure(plt, writer: _Writer, trace: Trace, width: float) -> None:
    busy = {link: points for link, points in sorted(trace.fifo.items()) if any(size for _, size in points)}
    idle = sorted(set(trace.fifo) - set(busy))
    chosen = sorted(sorted(busy, key=lambda link: (-max(s for _, s in busy[link]), link))[:MAX_SERIES])
    series = {link: busy[link] for link in chosen}
    fig, ax = plt.subplots(figsize=(width, 3.5))
    styles = {}
    for i, (link, points) in enumerate(series.items()):
        style = _style(i)
        styles[link] = style
        ax.step([t for t, _ in points], [size for _, size in points], where="post", linestyle=style[0],
                marker=style[1] or None, markevery=max(1, len(points) // 10), fillstyle="none", label=link)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("transmit FIFO (bytes)")
    _legend(ax, width)
    ax.grid(alpha=0.3)
    _plain(ax)
    together = coinciding(series)
    writer.inspect["fifo"] = {"styles": styles, "coinciding": together, "idle": idle}
    note = "".join(f"; {' and '.join(group)} coincide" for group in together)
    if idle:
        note += f"; never queued, not drawn: {', '.join(idle[:8])}{' …' if len(idle) > 8 else ''}"
    if len(busy) > len(chosen):
        note += f"; the {len(chosen)} links with the highest peaks of {len(busy)}"
    writer.save(fig, "fifo", "Transmit FIFO occupancy of each link" + note)


def _compare_figure(plt, writer: _Writer, summaries: dict[str, dict], width: float, width_given: bool) -> None:
    metrics = [("throughput_Bps", "throughput (B/s)", 0.0), ("efficiency", "efficiency", 0.0),
               ("delay_mean_s", "mean delay (s)", RESIDUE_S), ("jitter_s", "jitter (s)", RESIDUE_S)]
    names = list(summaries)
    flow_keys = list(dict.fromkeys(f"{f['from']} → {f['to']}" for s in summaries.values() for f in s["flows"]))
    if not flow_keys:
        return
    # a width given is kept (a paper's column); the default grows with the bars, up to 24 inches
    wide = width if width_given else min(24.0, max(width, 0.35 * len(flow_keys) * len(names)))
    fig, axes = plt.subplots(len(metrics), 1, figsize=(wide, 2.6 * len(metrics)), squeeze=False, sharex=True)
    bar = 0.8 / len(names)
    scales, not_drawn = {}, {}
    for ax, (key, label, residue) in zip(axes[:, 0], metrics):
        panel = []
        rows = []
        for i, name in enumerate(names):
            values = {f"{f['from']} → {f['to']}": f.get(key) for f in summaries[name]["flows"]}
            heights = [values.get(k) for k in flow_keys]
            panel += [h for h in heights if h is not None]
            rows.append((i, name, heights))
        logarithmic = log_scale_needed(panel, residue)
        missing = 0
        for i, name, heights in rows:
            if logarithmic:
                missing += sum(1 for h in heights if h is None or h <= residue)
                heights = [h if h is not None and h > residue else 0.0 for h in heights]
            else:
                heights = [h if h is not None else 0.0 for h in heights]
            ax.bar([j + i * bar for j in range(len(flow_keys))], heights, bar, label=name)
        if logarithmic:
            ax.set_yscale("log")
            label += ", log scale"
            not_drawn[key] = missing
        scales[key] = ax.get_yscale()
        _plain(ax)
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    axes[-1, 0].set_xticks([j + bar * (len(names) - 1) / 2 for j in range(len(flow_keys))],
                           [_short(k) for k in flow_keys], fontsize="x-small")  # (the panels share them)
    _legend(axes[0, 0], wide)
    writer.inspect["compare"] = {"yscale": scales, "not_drawn": not_drawn}
    note = "".join(f"; {key}: {n} values of zero or below 1 ns (or missing) not drawn on the log axis"
                   for key, n in not_drawn.items() if n)
    writer.save(fig, "compare", "Per flow, side by side: " + ", ".join(names) + note)


# -- the page -------------------------------------------------------------------------------------


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
