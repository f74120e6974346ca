"""Traces appended across daemon restarts: each start writes a ``run`` header, and ``hilgate report``
shows one run (the last unless told), saying so, instead of merging runs whose packet ids restart."""

import json
import subprocess
import sys

from daemon_kit import unique
from hilgate.report.tracedata import load_trace, pick_run, trace_runs


def test_each_daemon_start_writes_a_run_header(daemon_of):
    a = unique("a")
    daemon = daemon_of(f"""\
name: header
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links: {{{a}: {{vehicle: v}}}}
""", [a])
    daemon.stop()
    events = daemon.trace_events()
    header = events[0]
    assert header["ev"] == "run" and header["scene"] == "header" and header["t"] == 0.0
    assert len(header["run"]) == 12 and header["start"].endswith("+00:00") and header["version"]


def two_runs(path):
    lines = []
    for run, sizes in (("aaaa", [10, 11, 12]), ("bbbb", [20, 21])):
        lines.append({"t": 0.0, "ev": "run", "run": run, "start": f"2026-11-21T10:00:0{len(lines)}+00:00",
                      "scene": "s", "version": "x"})
        for pkt, size in enumerate(sizes, 1):  # packet ids restart at 1 in every run
            lines.append({"t": pkt * 1.0, "ev": "enq", "link": "la", "pkt": pkt, "src": "la", "dst": "lb",
                          "size": size, "fifo_bytes": size})
            lines.append({"t": pkt * 1.0 + 0.5, "ev": "rx", "link": "lb", "pkt": pkt, "src": "la", "dst": "lb",
                          "size": size, "fifo_bytes": 0})
    text = "".join(json.dumps(line) + "\n" for line in lines)
    path.write_text(text + '{"t": 9.0, "ev": "tx", "li')  # the last line cut short by a SIGKILL


def test_report_takes_one_run_of_a_trace_with_several(tmp_path):
    trace = tmp_path / "trace.jsonl"
    two_runs(trace)
    runs = trace_runs(str(trace))
    assert [r.id for r in runs] == ["aaaa", "bbbb"]
    last = load_trace(str(trace), run=pick_run(runs, None))
    first = load_trace(str(trace), run=pick_run(runs, "1"))
    assert sorted(p.size for p in last.packets.values()) == [20, 21]
    assert sorted(p.size for p in first.packets.values()) == [10, 11, 12]
    assert pick_run(runs, "bb").id == "bbbb" and pick_run(runs, "-2").id == "aaaa"
    result = subprocess.run([sys.executable, "-m", "hilgate", "report", str(trace), "--out", str(tmp_path / "r"),
                             "--csv"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "holds 2 runs" in result.stderr and "showing the last: run bbbb" in result.stderr
    wrong = subprocess.run([sys.executable, "-m", "hilgate", "report", str(trace), "--out", str(tmp_path / "r2"),
                            "--run", "zzzz"], capture_output=True, text=True, timeout=120)
    assert wrong.returncode == 1 and "no run 'zzzz'" in wrong.stderr and "Traceback" not in wrong.stderr


def test_a_trace_cut_by_logrotate_keeps_its_headless_start_as_a_run(tmp_path):
    trace = tmp_path / "trace.jsonl"
    two_runs(trace)
    text = trace.read_text()
    tail_of_an_earlier_run = json.dumps({"t": 7.0, "ev": "enq", "link": "la", "pkt": 9, "src": "la", "dst": "lb",
                                         "size": 99, "fifo_bytes": 0}) + "\n"
    trace.write_text(tail_of_an_earlier_run + text)
    runs = trace_runs(str(trace))
    assert [r.id for r in runs] == ["(before the first run line)", "aaaa", "bbbb"]
    assert [p.size for p in load_trace(str(trace), run=runs[0]).packets.values()] == [99]
