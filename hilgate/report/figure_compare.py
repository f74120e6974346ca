"""Several summaries side by side (one per MAC protocol, say): grouped bars of throughput, efficiency, delay and
jitter per flow."""

from __future__ import annotations

from .figure_kit import RESIDUE_S, FigureWriter, log_scale_needed, plain_ticks
from .figure_layout import legend_above, short_label


def compare_figure(plt, writer: FigureWriter, summaries: dict[str, dict], width: float, width_given: bool) -> None:
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
        missing = _bars(ax, summaries, names, flow_keys, key, residue, bar)
        if missing is not None:
            ax.set_yscale("log")
            label += ", log scale"
            not_drawn[key] = missing
        scales[key] = ax.get_yscale()
        plain_ticks(ax)
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    axes[-1, 0].set_xticks([j + bar * (len(names) - 1) / 2 for j in range(len(flow_keys))],
                           [short_label(k) for k in flow_keys], fontsize="x-small")  # (the panels share them)
    legend_above(axes[0, 0], wide)
    writer.inspect["compare"] = {"yscale": scales, "not_drawn": not_drawn}
    note = "".join(f"; {key}: {n} values of zero or below 1 ns (or missing) not drawn on the log axis"
                   for key, n in not_drawn.items() if n)
    writer.save(fig, "compare", "Per flow, side by side: " + ", ".join(names) + note)


def _bars(ax, summaries: dict[str, dict], names: list[str], flow_keys: list[str], key: str, residue: float,
          bar: float) -> int | None:
    """One metric's panel: a bar per summary per flow.  Returns None on a linear axis; on a logarithmic one
    (the values span more than ``LOG_SPAN``), how many values it cannot show (zero, a residue, missing)."""
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
    return missing if logarithmic else None
