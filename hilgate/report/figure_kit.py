"""What every figure of ``hilgate report`` shares: the numbers that shape them (resolution, width, when an axis
turns logarithmic, when a timeline is counted per window), the series they are drawn from (distances, flows,
delays), line styles, and :class:`FigureWriter`, which lays a figure out, checks it and saves it with its caption."""

from __future__ import annotations

import itertools
import json
import logging
import math
import os
import warnings
from collections import defaultdict

from .figure_layout import CAPTION_PT, caption_lines, collisions, fit_legends, inside, legible, outside
from .tracedata import Packet, ReportError, Trace

log = logging.getLogger(__name__)

REAL_SHADE = "#9ecae1"

MISSING_MATPLOTLIB = ("hilgate report needs matplotlib, an optional extra: pip install 'hilgate[report]' "
                      "(or pip install matplotlib); --csv tables need nothing more")

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

STYLES = ["-", "--", ":", "-."]

MARKERS = ["", "o", "s", "^", "v", "D"]

POINT_MARKERS = ["o", "s", "^", "v", "D", "P", "X", "<", ">", "h"]


def distances(trace: Trace, vehicles: list[str]) -> dict[tuple[str, str], list[tuple[float, float]]]:
    series = {}
    for a, b in itertools.combinations(vehicles, 2):
        pa, pb = dict(trace.poses.get(a, [])), dict(trace.poses.get(b, []))
        series[(a, b)] = [(t, math.dist(pa[t], pb[t])) for t in sorted(pa) if t in pb and pa[t] and pb[t]]
    return series


def by_flow(trace: Trace) -> dict[tuple[str, str], list[Packet]]:
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


def pyplot():
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


def plain_ticks(ax) -> None:
    """Plain tick values (no ``1e−13+8.8888933e−2`` offsets) on linear axes."""
    for axis, scale in ((ax.xaxis, ax.get_xscale()), (ax.yaxis, ax.get_yscale())):
        formatter = axis.get_major_formatter()
        if scale == "linear" and hasattr(formatter, "set_useOffset"):  # (not the tick labels a caller named)
            formatter.set_useOffset(False)
            formatter.set_scientific(False)


def seconds_or_ms(values: list[float]) -> tuple[float, str]:
    """Delays below a second read better in milliseconds."""
    return (1000.0, "ms") if values and max(values) < 1.0 else (1.0, "s")


def line_style(i: int) -> tuple[str, str]:
    """A line style and marker per series, different for the first 24."""
    return STYLES[i % len(STYLES)], MARKERS[(i // len(STYLES)) % len(MARKERS)]


def time_span(times: list[float]) -> tuple[float, float]:
    """A time axis' range: the activity, with a margin."""
    low, high = min(times), max(times)
    pad = 0.04 * (high - low) if high > low else max(0.5, abs(low) * 1e-6)
    return low - pad, high + pad


def check_dpi(dpi: float) -> None:
    if not (math.isfinite(dpi) and DPI_RANGE[0] <= dpi <= DPI_RANGE[1]):
        raise ReportError(f"--dpi {dpi:g}: give the PNGs' resolution in dots per inch, from {DPI_RANGE[0]:g} "
                          f"to {DPI_RANGE[1]:g} (journals ask 300)")


def check_pixels(fig, stem: str, dpi: float) -> None:
    width_in, height_in = fig.get_figwidth(), fig.get_figheight()
    if width_in * height_in * dpi * dpi > MAX_PIXELS:
        fits = int(math.sqrt(MAX_PIXELS / (width_in * height_in)))
        raise ReportError(f"--dpi {dpi:g}: {stem}.png would be {width_in:.1f} × {height_in:.1f} inches at {dpi:g} dpi, "
                          f"{width_in * height_in * dpi * dpi / 1e6:.0f} million pixels; give --dpi {fits} or less, "
                          f"or a smaller --width")


class FigureWriter:
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
            lines = caption_lines(caption, fig.get_figwidth())
            extra = (len(lines) * CAPTION_PT * 1.32 + 10) / 72
            height += extra
            fig.set_figheight(height)
            text = fig.text(0.012, 4 / 72 / height, "\n".join(lines), fontsize=CAPTION_PT, ha="left", va="bottom",
                            gid="caption")
        with warnings.catch_warnings(record=True) as complaints:
            warnings.simplefilter("always")
            fig.tight_layout(rect=(0, extra / height, 1, 1))
            if fit_legends(fig) | legible(fig)[0]:  # what moved takes other room: lay out again, check again
                fig.tight_layout(rect=(0, extra / height, 1, 1))
                fit_legends(fig)
        overlaps = legible(fig)[1]
        self.inspect.setdefault(stem, {}).update({
            "overlaps": overlaps, "collisions": collisions(fig, text), "outside": outside(fig), "caption": caption,
            "caption_drawn": text is not None, "caption_inside": text is not None and inside(fig, text),
            "width_in": fig.get_figwidth(), "layout": not any("tight" in str(w.message).lower() for w in complaints)})
        if "png" in self.formats:
            check_pixels(fig, stem, self.dpi)
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
