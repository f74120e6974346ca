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
                 "--csv"]) == 0
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
