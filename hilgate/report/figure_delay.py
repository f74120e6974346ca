"""The end-to-end delay of every delivered packet, per flow."""

from __future__ import annotations

from .figure_kit import (MAX_SERIES, POINT_MARKERS, RESIDUE_S, FigureWriter, coinciding, delays, log_scale_needed,
                         plain_ticks, seconds_or_ms)
from .figure_layout import legend_above
from .tracedata import Packet, Trace


def delay_figure(plt, writer: FigureWriter, trace: Trace, flows: dict[tuple[str, str], list[Packet]],
                 width: float) -> None:
    every = {flow: delays(trace, flow, packets) for flow, packets in flows.items()}
    every = {flow: points for flow, points in every.items() if points}
    chosen = sorted(sorted(every, key=lambda f: (-len(every[f]), f))[:MAX_SERIES])
    values = [d for flow in chosen for _, d in every[flow]]
    logarithmic = log_scale_needed(values, RESIDUE_S)
    shown = [d for d in values if d > RESIDUE_S] if logarithmic else values
    factor, unit = seconds_or_ms(shown)
    fig, ax = plt.subplots(figsize=(width, 3.5))
    series, left_out = _draw(ax, chosen, every, logarithmic, factor)
    if logarithmic:
        ax.set_yscale("log")
    ax.set_xlabel("time of delivery (s)")
    ax.set_ylabel(f"end-to-end delay ({unit}{', log scale' if logarithmic else ''})")
    plain_ticks(ax)
    legend_above(ax, width)
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


def _draw(ax, chosen: list[tuple[str, str]], every: dict[tuple[str, str], list[tuple[float, float]]],
          logarithmic: bool, factor: float) -> tuple[dict[str, list], int]:
    """Each chosen flow's delays as hollow marks (on a log axis, not those it cannot show); returns the
    series drawn and how many delays were left out."""
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
    return series, left_out
