"""Each link's transmit FIFO over time."""

from __future__ import annotations

from .figure_kit import MAX_SERIES, FigureWriter, coinciding, line_style, plain_ticks
from .figure_layout import legend_above
from .tracedata import Trace


def fifo_figure(plt, writer: FigureWriter, trace: Trace, width: float) -> None:
    busy = {link: points for link, points in sorted(trace.fifo.items()) if any(size for _, size in points)}
    idle = sorted(set(trace.fifo) - set(busy))
    chosen = sorted(sorted(busy, key=lambda link: (-max(s for _, s in busy[link]), link))[:MAX_SERIES])
    series = {link: busy[link] for link in chosen}
    fig, ax = plt.subplots(figsize=(width, 3.5))
    styles = {}
    for i, (link, points) in enumerate(series.items()):
        style = line_style(i)
        styles[link] = style
        ax.step([t for t, _ in points], [size for _, size in points], where="post", linestyle=style[0],
                marker=style[1] or None, markevery=max(1, len(points) // 10), fillstyle="none", label=link)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("transmit FIFO (bytes)")
    legend_above(ax, width)
    ax.grid(alpha=0.3)
    plain_ticks(ax)
    together = coinciding(series)
    writer.inspect["fifo"] = {"styles": styles, "coinciding": together, "idle": idle}
    note = "".join(f"; {' and '.join(group)} coincide" for group in together)
    if idle:
        note += f"; never queued, not drawn: {', '.join(idle[:8])}{' …' if len(idle) > 8 else ''}"
    if len(busy) > len(chosen):
        note += f"; the {len(chosen)} links with the highest peaks of {len(busy)}"
    writer.save(fig, "fifo", "Transmit FIFO occupancy of each link" + note)
