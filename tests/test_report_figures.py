"""Figures a reviewer accepts (issue 24, item 8), checked from what was drawn: no zero or sub-nanosecond
residue on a log axis (and the caption says so), tick labels that never overlap at any width,
overlapping series told apart, the flows' timelines on one time axis spanning their activity (issue 40
changed it from one axis per flow), the caption inside the figure files, backend periods shaded, and
an ``--out`` folder holding only this run's figures."""

from __future__ import annotations

import json
import os

import pytest

matplotlib = pytest.importorskip("matplotlib")

from PIL import Image  # noqa: E402  (matplotlib's own dependency)

from hilgate.cli import main  # noqa: E402
from hilgate.report.figures import RESIDUE_S, figures  # noqa: E402
from hilgate.report.tracedata import Packet, Trace, load_trace  # noqa: E402


def flow_trace(flows: dict[tuple[str, str], list[tuple[float, float]]]) -> Trace:
    """Packets of each flow as (time sent, delay), all delivered; FIFO levels per sender."""
    trace = Trace()
    pkt = 0
    for (src, dst), packets in flows.items():
        for t, delay in packets:
            pkt += 1
            packet = Packet(pkt, src, dst, 20, t_enq=t, t_tx=[t])
            packet.outcomes.append((t + delay, dst, "rx", None))
            trace.packets[pkt] = packet
            trace.fifo[src].append((t, 20))
            trace.fifo[src].append((t + 0.01, 0))
            trace.end = max(trace.end, t + delay)
    return trace


def test_zero_and_sub_nanosecond_delays_are_not_drawn_on_a_log_axis(tmp_path):
    # delays of 1 ms to 2 s (a log axis), plus exact zeros and floating-point residues of a zero
    delays = [0.001, 0.01, 0.2, 2.0, 0.0, 1e-13, 5e-10, 0.003]
    trace = flow_trace({("a", "b"): [(i * 1.0, d) for i, d in enumerate(delays)]})
    seen: dict = {}
    written = dict(figures(trace, {}, [], str(tmp_path), inspect=seen))
    assert seen["delay"]["yscale"] == "log"
    assert seen["delay"]["not_drawn"] == sum(d <= RESIDUE_S for d in delays) == 3
    assert "3 delays of zero or below 1 ns are not drawn on the log axis" in written["delay.png"]
    # on a linear axis (a span under 100x) a zero is a value like any other, drawn
    linear = flow_trace({("a", "b"): [(0.0, 0.0), (1.0, 0.01), (2.0, 0.02)]})
    seen = {}
    figures(linear, {}, [], str(tmp_path), inspect=seen)
    assert seen["delay"]["yscale"] == "linear" and seen["delay"]["not_drawn"] == 0


def test_bars_of_zero_are_not_drawn_on_a_log_axis_and_the_caption_says_so(tmp_path):
    flows = [{"from": "a", "to": "b", "throughput_Bps": 10.0, "efficiency": 0.5, "delay_mean_s": 100.0,
              "jitter_s": 0.0},
             {"from": "c", "to": "d", "throughput_Bps": 20.0, "efficiency": 0.6, "delay_mean_s": 0.05,
              "jitter_s": 1e-12}]
    summaries = {"one": {"flows": flows}, "two": {"flows": [dict(f, delay_mean_s=0.0) for f in flows]}}
    seen: dict = {}
    written = dict(figures(Trace(), summaries, [], str(tmp_path), inspect=seen))
    assert seen["compare"]["yscale"]["delay_mean_s"] == "log"
    assert seen["compare"]["not_drawn"]["delay_mean_s"] == 2  # two.delay_mean_s: both 0
    assert "delay_mean_s: 2 values of zero or below 1 ns" in written["compare.png"]


@pytest.mark.parametrize("width", [2.5, 3.5, None, 24.0])
def test_tick_labels_never_overlap_at_any_width(tmp_path, width):
    """Long link names, eight flows of four MACs, at a paper's column width, the default (whose bars
    of many flows grow wider) and a wide one: no two texts overlap, the layout holds, the caption drawn
    (``--captions``) is in the figure, and a width asked for is the width drawn.  (At 100 dpi: the
    layout is in inches and points, whatever the PNG's resolution.)"""
    names = [f"vehicle_{i:02d}_acoustic_modem_link" for i in range(8)]
    flows = {(names[i], names[(i + 1) % 8]): [(t * 0.7 + i * 123.456, 0.05 + 0.001 * t) for t in range(40)]
             for i in range(8)}
    trace = flow_trace(flows)
    summaries = {f"mac_{m}": {"flows": [{"from": a, "to": b, "throughput_Bps": 1000.0 * (m + 1) * (i + 1),
                                         "efficiency": 0.1 * i, "delay_mean_s": 0.01 * (i + 1), "jitter_s": 0.001}
                                        for i, (a, b) in enumerate(flows)]} for m in range(4)}
    trace.poses.update({name: [(t * 1.0, [t * 10.0 + i, 0.0, 0.0]) for t in range(50)]
                        for i, name in enumerate(names[:4])})
    seen: dict = {}
    written = figures(trace, summaries, names[:4], str(tmp_path), inspect=seen, width=width, dpi=100, captions=True)
    assert {name for name, _ in written} == {"distance.png", "timeline.png", "delay.png", "fifo.png", "compare.png"}
    for stem, drawn in seen.items():
        assert drawn["overlaps"] == 0, (stem, width)  # tick labels of one axis
        assert drawn["collisions"] == 0, (stem, width)  # tick labels, axis labels, legends, caption
        assert drawn["outside"] == 0, (stem, width)  # none of them off the figure
        assert drawn["caption_inside"] and drawn["layout"], (stem, width)
        assert drawn["width_in"] == width if width is not None else 9.0 <= drawn["width_in"] <= 24.0
    with Image.open(tmp_path / "compare.png") as image:
        assert image.width <= 24 * 100 + 1


def test_overlapping_series_are_told_apart(tmp_path):
    same = [(t * 1.0, 0.1) for t in range(20)]
    trace = flow_trace({("a", "b"): same, ("c", "d"): same})
    seen: dict = {}
    written = dict(figures(trace, {}, [], str(tmp_path), inspect=seen))
    assert seen["fifo"]["coinciding"] == [["a", "c"]]
    assert len(set(seen["fifo"]["styles"].values())) == 2
    assert "a and c coincide" in written["fifo.png"]
    assert seen["delay"]["coinciding"] == [["a → b", "c → d"]] and "hollow marks" in written["delay.png"]


def test_the_flows_timelines_share_one_time_axis_spanning_their_activity(tmp_path):
    trace = flow_trace({("a", "b"): [(t * 0.5, 0.1) for t in range(20)],          # 0 .. 10 s
                        ("c", "d"): [(3000 + t * 0.5, 0.1) for t in range(20)]})  # 3000 .. 3010 s
    seen: dict = {}
    written = dict(figures(trace, {}, [], str(tmp_path), inspect=seen))
    low, high = seen["timeline"]["xlim"]
    assert -130 < low <= 0 and 3009.6 < high < 3140
    assert "the panels share one time axis" in written["timeline.png"]


def test_the_caption_is_in_the_figure_files(tmp_path):
    trace = flow_trace({("a", "b"): [(t * 1.0, 0.1) for t in range(10)]})
    seen: dict = {}
    written = dict(figures(trace, {}, [], str(tmp_path), formats=("png", "svg", "pdf"), subtitle="scene s, seed 9",
                           inspect=seen, captions=True))
    caption = written["timeline.png"]
    assert "scene s, seed 9" in caption and seen["timeline"]["caption_inside"]
    with Image.open(tmp_path / "timeline.png") as image:
        assert image.info["Description"] == caption
    assert "<dc:description>" in (tmp_path / "timeline.svg").read_text()
    assert b"/Subject" in (tmp_path / "timeline.pdf").read_bytes()


def test_backend_periods_are_shaded_on_the_timelines(tmp_path):
    view = {"links": {"la": {"backend": "sim"}, "lb": {"backend": "sim"}}}
    real = {"links": {"la": {"backend": "evologics"}, "lb": {"backend": "sim"}}}
    lines = [{"t": 0.0, "ev": "run", "run": "r", "scene": "s", "scene_view": view}]
    for i in range(30):
        t = i * 1.0
        if t == 10.0:
            lines.append({"t": t, "ev": "reload", "scene": "s", "scene_view": real})
        if t == 20.0:
            lines.append({"t": t, "ev": "reload", "scene": "s", "scene_view": view})
        if not 10 <= t < 20:
            lines.append({"t": t, "ev": "tx", "link": "la", "pkt": i, "src": "la", "dst": "lb", "size": 9,
                          "fifo_bytes": 0})
            lines.append({"t": t + 0.2, "ev": "rx", "link": "lb", "pkt": i, "src": "la", "dst": "lb", "size": 9,
                          "fifo_bytes": 0})
    path = tmp_path / "trace.jsonl"
    path.write_text("".join(json.dumps(line) + "\n" for line in lines))
    trace = load_trace(str(path))
    assert trace.real_periods("la") == [(10.0, 20.0, "evologics")] and trace.real_periods("lb") == []
    seen: dict = {}
    written = dict(figures(trace, {}, [], str(tmp_path), inspect=seen))
    assert seen["timeline"]["real_periods"] == {"la → lb": [(10.0, 20.0, "evologics", "la")]}
    assert "shaded: a link of the flow on a real modem" in written["timeline.png"]


def test_the_out_folder_holds_only_this_runs_figures(tmp_path):
    trace = tmp_path / "t.jsonl"
    lines = [{"t": i * 1.0, "ev": ev, "link": link, "pkt": i, "src": "la", "dst": "lb", "size": 9, "fifo_bytes": 9}
             for i in range(5) for ev, link in (("tx", "la"), ("rx", "lb"))]
    trace.write_text("".join(json.dumps(line) + "\n" for line in lines))
    summary = tmp_path / "s.json"
    summary.write_text(json.dumps({"scene": "s", "seed": 1, "flows": [
        {"from": "la", "to": "lb", "throughput_Bps": 1.0, "efficiency": 1.0, "delay_mean_s": 0.1, "jitter_s": 0.0}]}))
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["report", str(trace), str(summary), "--out", str(out), "--csv", "--format", "svg"]) == 0
    assert {"compare.png", "compare.svg", "summaries.csv", "timeline.svg"} <= set(os.listdir(out))
    assert main(["report", str(trace), "--out", str(out)]) == 0
    assert sorted(os.listdir(out)) == ["delay.png", "fifo.png", "index.html", "notes.txt", "timeline.png"]
