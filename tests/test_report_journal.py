"""Figures a journal takes (issue 40, item 5), checked in the files written, not in pixels: the panels of
the timeline on one time axis (shared, aligned, one label), the legend in words, one vocabulary of loss
causes for the report's figures and tables and the web view, captions in the files' metadata and drawn
only when asked, PNG at 300 dpi unless asked otherwise, PDF with embedded TrueType fonts.

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

from PIL import Image  # noqa: E402  (matplotlib's own dependency)

from hilgate.cli import main  # noqa: E402
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


def ticks(axes: ET.Element, axis: str = "xtick_") -> list[tuple[float, list[str]]]:
    """(x of the tick mark, its label's texts) of each tick of the axes' x axis."""
    out = []
    for tick in groups(axes, axis):
        marks = [float(use.get("x")) for use in tick.iter(f"{SVG_NS}use") if use.get("x") is not None
                 and "#m" in (use.get(XLINK) or "")]
        out.append((marks[0] if marks else float("nan"), texts(tick)))
    return out


def frame_of(axes: ET.Element) -> tuple[float, float]:
    """The left and right edges of the axes' background (its first patch)."""
    patch = groups(axes, "patch_")[0]
    path = next(patch.iter(f"{SVG_NS}path")).get("d")
    xs = [float(x) for x in re.findall(r"[ML] ([-\d.]+) [-\d.]+", path)]
    return min(xs), max(xs)


def legend_texts(root: ET.Element) -> list[str]:
    return [text for legend in groups(root, "legend_") for text in texts(legend)]


def pdf_info(path) -> dict[str, str]:
    """The PDF's document information (matplotlib writes it uncompressed): text strings in () or as
    UTF-16 in <FEFF…>."""
    data = path.read_bytes()
    info = {}
    for key, literal, hexa in re.findall(rb"/(Title|Subject|Creator|Producer) (?:\(((?:\\.|[^\\)])*)\)|<([0-9A-Fa-f]+)>)",
                                         data):
        if hexa:
            value = bytes.fromhex(hexa.decode()).decode("utf-16")
        else:
            value = re.sub(rb"\\(.)", rb"\1", literal).decode("latin-1")
        info[key.decode()] = value
    return info


# -- one time axis ----------------------------------------------------------------------------------


def test_the_timeline_panels_share_one_time_axis(tmp_path):
    """Three flows active at different times: every panel shows the same seconds, its tick marks at the
    same places, its left and right edges aligned; only the bottom one has tick labels, and the figure
    one 'time (s)'."""
    trace = lossy_trace({("a", "b"): (0.0, 12.0), ("c", "d"): (40.0, 70.0), ("e", "f"): (20.0, 90.0)})
    seen: dict = {}
    figures(trace, {}, [], str(tmp_path), formats=("svg",), inspect=seen)
    root = svg_tree(tmp_path / "timeline.svg")
    panels = groups(root, "axes_")
    assert len(panels) == 3
    marks = [[x for x, _ in ticks(panel)] for panel in panels]
    assert marks[0] and all(m == marks[0] for m in marks), marks
    assert len({frame_of(panel) for panel in panels}) == 1
    labelled = [[label for _, label in ticks(panel) if label] for panel in panels]
    assert labelled[:-1] == [[], []] and len(labelled[-1]) >= 3
    assert texts(root).count("time (s)") == 1
    # the one axis spans every flow's activity
    low, high = seen["timeline"]["xlim"]
    assert low <= 0.0 and high >= 90.2


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


def test_the_docs_table_of_causes_is_the_one_the_code_uses():
    """docs/reports.md shows the channel's causes in words: the rows are checked against the table, so
    the page cannot drift from it."""
    from hilgate.report.causes import RECEIVED, words

    page = open(os.path.join(REPO, "docs", "reports.md"), encoding="utf-8").read()
    rows = re.findall(r"^\| `(\w+)` \| ([^|]+?) \|$", page, re.M)
    assert len(rows) >= 8 and {code for code, _ in rows} >= {"prop", "col", "mult", "range", "fifo"}
    assert [(code, text) for code, text in rows if text != words(code)] == []
    assert f'is "{RECEIVED.words}"' in page


# -- captions, resolution, fonts --------------------------------------------------------------------


def test_captions_are_in_the_metadata_and_on_the_image_only_when_asked(tmp_path):
    trace = lossy_trace({("a", "b"): (0.0, 10.0)})
    plain, drawn = tmp_path / "plain", tmp_path / "drawn"
    plain.mkdir(), drawn.mkdir()
    written = dict(figures(trace, {}, [], str(plain), formats=("png", "svg", "pdf"), subtitle="scene s, seed 9"))
    caption = written["timeline.png"]
    assert "scene s, seed 9" in caption and "sent, received" in caption
    with Image.open(plain / "timeline.png") as image:
        assert image.info["Description"] == caption
    assert pdf_info(plain / "timeline.pdf")["Subject"] == caption
    root = svg_tree(plain / "timeline.svg")
    [description] = [node.text for node in root.iter("{http://purl.org/dc/elements/1.1/}description")]
    assert description == caption
    assert groups(root, "caption") == [] and not any("seed 9" in text for text in texts(root))

    figures(trace, {}, [], str(drawn), formats=("svg",), subtitle="scene s, seed 9", captions=True)
    [drawn_caption] = groups(svg_tree(drawn / "timeline.svg"), "caption")
    assert " ".join(texts(drawn_caption)).replace("\n", " ").startswith("Packets of each flow")


def test_png_is_300_dpi_by_default_and_as_asked(tmp_path):
    trace = lossy_trace({("a", "b"): (0.0, 10.0)})
    figures(trace, {}, [], str(tmp_path), width=3.5)
    with Image.open(tmp_path / "timeline.png") as image:
        assert image.info["dpi"] == pytest.approx((300, 300), abs=0.05)  # (PNG stores whole dots per metre)
        assert image.width == pytest.approx(3.5 * 300, abs=2)
    figures(trace, {}, [], str(tmp_path), width=3.5, dpi=600)
    with Image.open(tmp_path / "delay.png") as image:
        assert image.info["dpi"] == pytest.approx((600, 600), abs=0.05)  # (PNG stores whole dots per metre)
        assert image.width == pytest.approx(3.5 * 600, abs=2)


def test_a_png_too_large_for_memory_is_refused_with_the_dpi_that_fits(tmp_path):
    from hilgate.report.tracedata import ReportError

    trace = lossy_trace({("a", "b"): (0.0, 5.0), ("c", "d"): (0.0, 5.0), ("e", "f"): (0.0, 5.0)})
    with pytest.raises(ReportError, match=r"--dpi 1200: timeline.png would be 40.0 × .* give --dpi \d+ or less"):
        figures(trace, {}, [], str(tmp_path), width=40.0, dpi=1200)
    assert not (tmp_path / "timeline.png").exists()


def test_pdf_embeds_truetype_fonts(tmp_path):
    """Journals' PDF checks refuse Type 3 fonts (matplotlib's default): the fonts are TrueType, embedded."""
    figures(lossy_trace({("a", "b"): (0.0, 10.0)}), {}, [], str(tmp_path), formats=("pdf",))
    data = (tmp_path / "timeline.pdf").read_bytes()
    assert b"/Subtype /Type3" not in data and b"/FontFile2" in data


def test_the_command_takes_dpi_and_captions(tmp_path, capsys):
    trace = tmp_path / "t.jsonl"
    lines = [{"t": i * 1.0 + dt, "ev": ev, "link": link, "pkt": i, "src": "la", "dst": "lb", "size": 9,
              "fifo_bytes": 0} for i in range(6) for ev, link, dt in (("tx", "la", 0.0), ("rx", "lb", 0.2))]
    trace.write_text("".join(json.dumps(line) + "\n" for line in lines))
    out = tmp_path / "out"
    assert main(["report", str(trace), "--out", str(out), "--dpi", "150", "--captions", "--format", "svg"]) == 0
    with Image.open(out / "timeline.png") as image:
        assert image.info["dpi"] == pytest.approx((150, 150), abs=0.05)  # (PNG stores whole dots per metre)
    assert groups(svg_tree(out / "timeline.svg"), "caption")
    for bad in ("0", "5000", "nan"):
        assert main(["report", str(trace), "--out", str(out), "--dpi", bad]) != 0
        assert "--dpi" in capsys.readouterr().err
