"""The distance between vehicles over time, from the trace's pose samples."""

from __future__ import annotations

from .figure_kit import FigureWriter, coinciding, distances, line_style, plain_ticks
from .figure_layout import legend_above
from .tracedata import Trace


def distance_figure(plt, writer: FigureWriter, trace: Trace, vehicles: list[str], width: float) -> None:
    pairs = {pair: points for pair, points in distances(trace, vehicles).items() if points}
    if not pairs:
        return
    fig, ax = plt.subplots(figsize=(width, 3.5))
    series = {f"{a} – {b}": points for (a, b), points in pairs.items()}
    together = coinciding(series)
    styles = {}
    for i, (label, points) in enumerate(series.items()):
        style = line_style(i)
        styles[label] = style
        ax.plot([t for t, _ in points], [d for _, d in points], linestyle=style[0], marker=style[1] or None,
                markevery=max(1, len(points) // 12), fillstyle="none", label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance (m)")
    plain_ticks(ax)
    legend_above(ax, width)
    ax.grid(alpha=0.3)
    writer.inspect["distance"] = {"styles": styles, "coinciding": together}
    note = "".join(f"; {' and '.join(group)} coincide" for group in together)
    writer.save(fig, "distance", "Distance between vehicles" + note)
