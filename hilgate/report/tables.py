"""The readable per-flow and per-link tables printed at the end of ``hilgate sim``; loss causes in the
words of :mod:`.causes`, as the report's figures name them."""

from __future__ import annotations

from typing import Any

from .causes import legend_order, words


def _fmt(value: Any, unit: str = "", scale: float = 1.0, digits: int = 3) -> str:
    if value is None:
        return "-"
    return f"{value * scale:.{digits}f}{unit}"


def _render(headers: list[str], rows: list[list[str]], left: int = 1) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells: list[str]) -> str:
        return "  ".join(c.ljust(w) if i < left else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    return "\n".join([line(headers), line(["-" * w for w in widths]), *(line(r) for r in rows)])


def format_summary(summary: dict[str, Any]) -> str:
    parts = [f"scene {summary['scene']!r}  seed {summary['seed']}  {summary['sim_time_s']:g} s simulated "
             f"in {summary['wall_time_s']:.3f} s"]
    if summary["flows"]:
        shown = ("prop", "col", "mult", "range")
        others = sorted({cause for f in summary["flows"] for cause in f["lost"]} - set(shown),
                        key=legend_order)  # band, modulation
        named = [words(cause) for cause in shown + tuple(others)]
        headers = ["flow", "offered", words("fifo"), "tx", "rx", f"lost: {named[0]}", *named[1:],
                   "B/s", "effic.", "delay mean", "p95", "jitter"]
        rows = []
        for f in summary["flows"]:
            lost = f["lost"]
            rows.append([
                f"{f['from']} -> {f['to']}", str(f["offered"]), str(f["fifo_drops"]), str(f["tx_packets"]),
                str(f["rx_packets"]), *(str(lost.get(cause, 0)) for cause in shown + tuple(others)),
                _fmt(f["throughput_Bps"], digits=1), _fmt(f["efficiency"], digits=3),
                _fmt(f["delay_mean_s"], " ms", 1e3, 1), _fmt(f["delay_p95_s"], " ms", 1e3, 1),
                _fmt(f["jitter_s"], " ms", 1e3, 1),
            ])
        parts.append(_render(headers, rows))
    if summary["links"]:
        headers = ["link", "tx", "rx", "fifo drops", "fifo peak B"]
        rows = [[l["id"], str(l["tx_packets"]), str(l["rx_packets"]), str(l["fifo_drops"]), str(l["fifo_peak_bytes"])]
                for l in summary["links"]]
        parts.append(_render(headers, rows))
    return "\n\n".join(parts)
