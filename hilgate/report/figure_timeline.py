"""Per flow, a timeline of packets sent, received and lost by cause, the panels on one time axis, with the
periods a link of the flow was on a real modem shaded."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from .causes import RECEIVED, legend_order
from .causes import colour as cause_colour
from .causes import words as cause_words
from .figure_kit import DENSE, MAX_PANELS, REAL_SHADE, FigureWriter, plain_ticks, time_span
from .figure_layout import legend_above, short_label
from .tracedata import Packet, Trace


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


def timeline_figure(plt, writer: FigureWriter, trace: Trace, flows: dict[tuple[str, str], list[Packet]],
                    width: float) -> None:
    """One panel per flow, on one time axis: a reader compares when flows were busy, lost frames or
    were on a real modem by looking down the page, as a journal's figure of stacked panels reads."""
    chosen = _busiest(flows, MAX_PANELS)
    fig, axes = plt.subplots(len(chosen), 1, figsize=(width, 1.0 + 1.45 * len(chosen)), squeeze=False,
                             sharex=True)
    times = {flow: _activity(flows[flow]) for flow in chosen}
    every = [t for flow in chosen for t in times[flow][3]]
    low, high = time_span(every) if every else (0.0, 1.0)
    bin_s = (high - low) / 120 if high > low else 1.0  # (the same windows in every dense panel)
    aggregated, shaded = [], {}
    handles: dict[str, Any] = {}
    ranks: dict[str, tuple] = {}  # the legend's order: sent, received, losses as the causes' table lists them
    for ax, flow in zip(axes[:, 0], chosen):
        sent, received, lost_by_cause, _ = times[flow]
        if len(sent) > DENSE:  # a solid band as marks: rates per window instead
            aggregated.append(f"{flow[0]} → {flow[1]}")
            _rates(ax, sent, received, lost_by_cause, low, bin_s, handles, ranks)
        else:
            _marks(ax, sent, received, lost_by_cause, handles, ranks)
        periods = _real_periods(ax, trace, flow, low, high, handles)
        if periods:
            shaded[f"{flow[0]} → {flow[1]}"] = periods
        plain_ticks(ax)
        ax.text(0.005, 0.97, short_label(f"{flow[0]} → {flow[1]}", max(16, int(width * 72 * 0.8 / (8.3 * 0.62)))),
                transform=ax.transAxes, fontsize="small", va="top", ha="left",
                bbox={"facecolor": "white", "alpha": 0.8, "lw": 0, "pad": 1})
        ax.grid(axis="x", alpha=0.3)
    axes[0, 0].set_xlim(low, high)  # (shared: every panel's)
    axes[-1, 0].set_xlabel("time (s)")
    fig.align_ylabels(axes[:, 0])
    labels = sorted(handles, key=lambda label: ranks.get(label, (2,)))
    legend_above(axes[0, 0], width, [handles[label] for label in labels], labels)
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


def _rates(ax, sent: list[float], received: list[float], lost_by_cause: dict[str | None, list[float]], low: float,
           bin_s: float, handles: dict[str, Any], ranks: dict[str, tuple]) -> None:
    """A dense flow's panel: sent, received and lost packets counted per window (the same 120 windows in every
    dense panel), as steps."""
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
              (1, legend_order(cause))) for cause in sorted(lost_by_cause, key=legend_order)]:
        if moments:
            values = rate(moments)
            peak = max(peak, max(values))
            handles[label] = ax.step(edges[:-1], values, where="post", color=colour, label=label)[0]
            ranks[label] = rank
    ax.set_ylim(0, peak * 1.45 or 1.0)
    ax.set_ylabel(f"per s ({bin_s:.3g} s bins)", fontsize="x-small")


def _marks(ax, sent: list[float], received: list[float], lost_by_cause: dict[str | None, list[float]],
           handles: dict[str, Any], ranks: dict[str, tuple]) -> None:
    """A flow's panel with a mark per packet: sent, received, and lost by cause on three rows."""
    handles["sent"] = ax.scatter(sent, [2] * len(sent), marker="|", s=40, color="#555555", label="sent")
    handles[RECEIVED.words] = ax.scatter(received, [1] * len(received), marker="|", s=40,
                                         color=RECEIVED.colour, label=RECEIVED.words)
    ranks.update({"sent": (0, 0), RECEIVED.words: (0, 1)})
    for cause in sorted(lost_by_cause, key=legend_order):
        label = f"lost: {cause_words(cause)}"
        handles[label] = ax.scatter(lost_by_cause[cause], [0] * len(lost_by_cause[cause]), marker="x", s=18,
                                    color=cause_colour(cause), label=label)
        ranks[label] = (1, legend_order(cause))
    ax.set_yticks([0, 1, 2], ["lost", RECEIVED.words, "sent"])
    ax.set_ylim(-0.6, 3.3)


def _real_periods(ax, trace: Trace, flow: tuple[str, str], low: float, high: float,
                  handles: dict[str, Any]) -> list[tuple]:
    """Shade (and name) the periods within ``low``–``high`` when a link of ``flow`` was on a real modem."""
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
    return periods
