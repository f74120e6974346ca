"""hilgate report on a small trace: every figure is a valid PNG, the page shows them, CSV tables, and a
clear message when matplotlib is missing."""

import json
import os
import subprocess
import sys

import matplotlib.image
import pytest

from hilgate.cli import main

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")

DPI = 100
"""The PNGs' resolution here: what these tests check (files, counts, what was drawn, the page) is laid out in
inches and points, the same at any resolution; at the report's 300 dpi each PNG took nine times the pixels."""


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    trace = folder / "exp1.jsonl"
    main(["sim", os.path.join(SCENES, "paper-exp1-rf.yaml"), "--until", "45", "--trace", str(trace),
          "--summary", str(folder / "csma.json"), "-q"])
    main(["sim", os.path.join(SCENES, "paper-exp1-rf.yaml"), "--until", "45", "--set", "links.*.mac=none",
          "--summary", str(folder / "none.json"), "-q"])
    return folder, trace


def test_every_figure_is_written_and_the_page_shows_them(runs, tmp_path):
    folder, trace = runs
    out = tmp_path / "report"
    assert main(["report", str(trace), str(folder / "csma.json"), str(folder / "none.json"), "--out", str(out),
                 "--csv", "--dpi", str(DPI)]) == 0
    pngs = sorted(p for p in os.listdir(out) if p.endswith(".png"))
    assert pngs == ["compare.png", "delay.png", "distance.png", "fifo.png", "timeline.png"]
    page = (out / "index.html").read_text()
    for png in pngs:
        data = (out / png).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        height, width, _ = matplotlib.image.imread(str(out / png)).shape
        assert width > 300 and height > 200
        assert f"src='{png}'" in page
    assert {"packets.csv", "fifo.csv", "distances.csv", "summaries.csv"} <= set(os.listdir(out))
    packets = (out / "packets.csv").read_text().splitlines()
    assert packets[0].startswith("pkt,src,dst") and len(packets) > 100
    assert any(",err,prop," in row for row in packets) and any(",err,col," in row for row in packets)


@pytest.mark.parametrize("extra", [[], ["--format", "pdf"], ["--format", "svg", "--format", "pdf", "--csv"]])
def test_the_files_counted_are_the_files_written(runs, tmp_path, capsys, extra):
    """Issue 40: ``--format pdf`` said "6 files" and wrote 11 (one per figure was counted, not one per
    format)."""
    folder, trace = runs
    out = tmp_path / "report"
    assert main(["report", str(trace), str(folder / "csma.json"), "--out", str(out), "--dpi", str(DPI), *extra]) == 0
    said = capsys.readouterr().out
    count = int(said.split(" files in ")[0].split()[-1])
    assert count == len(os.listdir(out)), (said, sorted(os.listdir(out)))


def test_missing_matplotlib_is_a_clear_message(runs, tmp_path):
    _, trace = runs
    code = ("import sys; sys.modules['matplotlib'] = None; from hilgate.cli import main; "
            f"sys.exit(main(['report', {str(trace)!r}, '--out', {str(tmp_path / 'r')!r}]))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 1
    assert "pip install 'hilgate[report]'" in result.stderr and "Traceback" not in result.stderr


def test_a_broken_trace_is_named(tmp_path):
    bad = tmp_path / "bad.jsonl"
    bad.write_text(json.dumps({"t": 0, "ev": "enq"}) + "\nnot json\n")
    result = subprocess.run([sys.executable, "-m", "hilgate", "report", str(bad), "--out", str(tmp_path / "r")],
                            capture_output=True, text=True)
    assert result.returncode == 1 and f"{bad}:2: not a JSON line" in result.stderr


def test_figures_are_fit_for_a_paper(runs, tmp_path):
    """Issue 14 item 5, checked from what was drawn (not pixels): coinciding series get their own styles
    and are named in the caption; a value span beyond 100× goes on a log scale; dense timelines are
    counted per window; SVG and PDF besides PNG; captions say what produced each figure."""
    from hilgate.report.figures import figures
    from hilgate.report.tracedata import load_trace

    folder, trace_path = runs
    trace = load_trace(str(trace_path))
    # a second pair of vehicles at exactly the same distances as the first: drawn over one another
    first = sorted(trace.poses)[:2]
    trace.poses["twin_a"] = list(trace.poses[first[0]])
    trace.poses["twin_b"] = list(trace.poses[first[1]])
    summaries = {name: json.loads((folder / f"{name}.json").read_text()) for name in ("csma", "none")}
    summaries["none"]["flows"][0]["delay_mean_s"] = 150.0  # one MAC's delay, decades above the rest
    seen: dict = {}
    written = figures(trace, summaries, [first[0], first[1], "twin_a", "twin_b"], str(tmp_path),
                      formats=("png", "svg", "pdf"), subtitle="scene paper-exp1-rf, seed 1", inspect=seen, dpi=DPI)
    styles = seen["distance"]["styles"]
    for group in seen["distance"]["coinciding"]:
        assert len({styles[name] for name in group}) == len(group)  # each one visible
    captions = dict(written)
    assert any(" coincide" in caption for caption in captions.values())
    assert all("scene paper-exp1-rf, seed 1" in caption for caption in captions.values())
    assert seen["compare"]["yscale"]["delay_mean_s"] == "log"
    assert seen["compare"]["yscale"]["efficiency"] == "linear"
    assert seen["delay"]["unit"] in ("ms", "s")
    for stem in ("distance", "delay", "compare", "timeline"):
        assert (tmp_path / f"{stem}.svg").read_bytes().lstrip().startswith((b"<?xml", b"<svg"))
        assert (tmp_path / f"{stem}.pdf").read_bytes()[:5] == b"%PDF-"


def test_a_dense_timeline_is_counted_per_window(tmp_path):
    from hilgate.report.figure_kit import DENSE
    from hilgate.report.figures import figures
    from hilgate.report.tracedata import Packet, Trace

    trace = Trace()
    for i in range(DENSE + 50):  # 4 Hz for 90 s: marks would make a solid band
        packet = Packet(i, "a", "b", 20, t_tx=[i * 0.25])
        packet.outcomes.append((i * 0.25 + 0.1, "b", "rx" if i % 7 else "err", None if i % 7 else "col"))
        trace.packets[i] = packet
    trace.end = 100.0
    seen: dict = {}
    figures(trace, {}, [], str(tmp_path), inspect=seen, dpi=DPI)
    assert seen["timeline"]["aggregated"] == ["a → b"]


def test_an_empty_or_inverted_window_is_an_error(runs, tmp_path, capsys):
    folder, trace = runs
    for window in (["30", "30"], ["30", "10"]):
        assert main(["report", str(trace), "--out", str(tmp_path), "--window", *window]) == 1
        assert "is empty: give START < END" in capsys.readouterr().err
