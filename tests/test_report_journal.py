"""Figures a journal takes (issue 40, item 5), checked in the files written, not in pixels: the legend in
words, one vocabulary of loss causes for the report's figures and tables and the web view.

An SVG written by matplotlib keeps every text it draws as a comment beside its glyphs, and every axes,
tick and legend as a group with an id: that is what these tests read."""

from __future__ import annotations

import csv
import json
import os
import re
import xml.etree.ElementTree as ET

import pytest

matplotlib = pytest.importorskip("matplotlib")

from hilgate.report.figures import figures  # noqa: E402
from hilgate.report.tracedata import Packet, Trace  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CODES = ("col", "prop", "mult", "range", "fifo", "no_reader", "not_a_frame")


def lossy_trace(flows: dict[tuple[str, str], tuple[float, float]], causes=("col", "prop", "mult", "range")) -> Trace:
    """Per flow, a packet a second from ``start`` to ``end``: sent, then received or lost to each of
    ``causes`` in turn (a ``fifo`` drop at the sender for one packet in five)."""
    trace = Trace()
    pkt = 0
    for (src, dst), (start, end) in flows.items():
        t, i = start, 0
        while t <= end:
            pkt += 1
            packet = Packet(pkt, src, dst, 20, t_enq=t)
            if i % 5 == 4:
                packet.outcomes.append((t, src, "drop", "fifo"))
            else:
                packet.t_tx.append(t)
                cause = causes[(i // 2) % len(causes)] if i % 2 else None
                packet.outcomes.append((t + 0.2, dst, "err" if cause else "rx", cause))
            trace.packets[pkt] = packet
            trace.fifo[src].append((t, 20))
            trace.end = max(trace.end, t + 0.2)
            t, i = t + 1.0, i + 1
    return trace


# -- reading an SVG written by matplotlib ------------------------------------------------------------

SVG_NS = "{http://www.w3.org/2000/svg}"
XLINK = "{http://www.w3.org/1999/xlink}href"


def svg_tree(path) -> ET.Element:
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    return ET.parse(path, parser).getroot()


def groups(root: ET.Element, prefix: str) -> list[ET.Element]:
    return [g for g in root.iter(f"{SVG_NS}g") if (g.get("id") or "").startswith(prefix)]


def texts(element: ET.Element) -> list[str]:
    """The texts drawn inside ``element``, in order (matplotlib writes each as a comment)."""
    return [node.text.strip() for node in element.iter() if node.tag is ET.Comment]


def legend_texts(root: ET.Element) -> list[str]:
    return [text for legend in groups(root, "legend_") for text in texts(legend)]


# -- words, one vocabulary --------------------------------------------------------------------------


def test_the_timeline_legend_and_labels_are_in_words(tmp_path):
    """In the causes' table's order, whichever panel shows a cause first."""
    trace = lossy_trace({("a", "b"): (0.0, 2.0), ("c", "d"): (0.0, 40.0)}, causes=("range", "col", "mult", "prop"))
    figures(trace, {}, [], str(tmp_path), formats=("svg",))
    root = svg_tree(tmp_path / "timeline.svg")
    legend = legend_texts(root)
    assert legend == ["sent", "received", "lost: channel errors", "lost: collision", "lost: collision + errors",
                      "lost: out of range", "lost: FIFO full"], legend
    [yaxis] = groups(groups(root, "axes_")[0], "matplotlib.axis_2")
    assert texts(yaxis) == ["lost", "received", "sent"]
    every = set(texts(root))
    assert not any(text.removeprefix("lost: ") in CODES for text in every), every


def test_a_dense_timeline_counts_losses_per_second_in_words(tmp_path):
    from hilgate.report.figures import DENSE

    trace = Trace()
    for i in range(DENSE + 50):
        packet = Packet(i, "a", "b", 20, t_tx=[i * 0.25])
        packet.outcomes.append((i * 0.25 + 0.1, "b", "rx" if i % 7 else "err", None if i % 7 else "col"))
        trace.packets[i] = packet
    figures(trace, {}, [], str(tmp_path), formats=("svg",))
    assert legend_texts(svg_tree(tmp_path / "timeline.svg")) == ["sent /s", "received /s", "lost: collision /s"]


def test_causes_read_the_same_in_the_figures_the_tables_and_the_web_view(tmp_path):
    """One table of words: the timeline's legend, the sim's printed table, packets.csv and the web view's
    SCENE all take theirs from it; the page's script keeps no words of its own."""
    from hilgate.report.causes import CAUSES, words
    from hilgate.report.figures import write_csv
    from hilgate.report.tables import format_summary
    from hilgate.web.picture import scene_message

    for code in CODES + ("band", "modulation", "no_pose", "closed"):
        assert code in CAUSES and words(code) != code and "_" not in words(code)
    assert words("something new") == "other (something new)"
    summary = {"scene": "s", "seed": 1, "sim_time_s": 10.0, "wall_time_s": 0.1, "links": [], "flows": [
        {"from": "a", "to": "b", "offered": 3, "fifo_drops": 0, "tx_packets": 3, "rx_packets": 1,
         "lost": {"prop": 1, "col": 1, "band": 1}, "throughput_Bps": 1.0, "efficiency": 0.3, "delay_mean_s": 0.1,
         "delay_p95_s": 0.1, "jitter_s": 0.0}]}
    [header] = [line for line in format_summary(summary).splitlines() if line.startswith("flow")]
    columns = re.split(r"\s{2,}", header)
    assert columns[2] == words("fifo") and columns[5] == f"lost: {words('prop')}"
    assert columns[6:10] == [words(code) for code in ("col", "mult", "range", "band")], columns
    trace = lossy_trace({("a", "b"): (0.0, 10.0)})
    write_csv(trace, {}, [], str(tmp_path))
    with open(tmp_path / "packets.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert {(row["cause"], row["cause_in_words"]) for row in rows if row["cause"]} == \
        {(code, words(code)) for code in ("col", "prop", "mult", "range", "fifo")}
    fates = scene_message({"links": {}}, "live")["fates"]
    assert {key: label for key, (label, _) in fates.items() if key != "rx"} == \
        {code: cause.words for code, cause in CAUSES.items()}
    script = open(os.path.join(REPO, "hilgate", "web", "static", "view.js"), encoding="utf-8").read()
    assert not any(json.dumps(cause.words) in script for cause in CAUSES.values())
