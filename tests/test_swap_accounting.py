"""Issue 24's check: a link pair swapped sim → emulated EvoLogics → sim while an application keeps
sending, in the real daemon.  Counters go on across the swaps, the summary has one segment per
backend period whose counts are the trace's, the trace has the reloads (with the scene), and
``hilgate fit`` finds the real links' frames from the trace alone, although the scene file says
"all simulated" by then.

application (socket GLI) → link a → [sim | EvoLogics driver → pty → emulated modem ea] → channel →
[sim | eb → pty → driver] → link b → application.
"""

import json
import os
import subprocess
import sys
import threading
import time

from daemon_kit import unique, wait_until
from hilgate.client import Link
from hilgate.fitcmd import run_fit
from hilgate.report.tracedata import load_trace



def scenes(tmp_path, a, b, ea, eb):
    vehicles = """\
seed: 3
channels: {ac: {speed_mps: 1500}}
vehicles:
  va: {pose: {static: [0, 0, 0]}}
  vb: {pose: {path: {start: [100, 0, 0], legs: [{to: [400, 0, 0], speed_mps: 5}]}}}
links:
"""
    modem = "packet: vl2b, bitrate_bps: 2000, tx_delay_s: 0.01, gli: [socket]"
    simulated = vehicles + f"""\
  {a}: {{vehicle: va, address: 1, {modem}}}
  {b}: {{vehicle: vb, address: 2, {modem}}}
"""
    pa, pb = tmp_path / "modem_a", tmp_path / "modem_b"
    # the emulated modems first: their ptys exist when the drivers open them; eb loses frames more
    # often the farther vb is (the receiver's error model applies), so the fit has both outcomes
    real = vehicles + f"""\
  {ea}: {{vehicle: va, address: 1, {modem}, emulate: {{protocol: evologics, pty: {pa}}}}}
  {eb}: {{vehicle: vb, address: 2, {modem}, error: {{unit: packet, expr: "d / 300"}},
         emulate: {{protocol: evologics, pty: {pb}}}}}
  {a}: {{vehicle: va, backend: evologics, port: {pa}, ack: false, address: 1, packet: vl2b, gli: [socket]}}
  {b}: {{vehicle: vb, backend: evologics, port: {pb}, ack: false, address: 2, packet: vl2b, gli: [socket]}}
"""
    return simulated, real


def wait(condition, what, daemon):
    wait_until(lambda: daemon.alive() and condition(), lambda: f"{what}\n{daemon.output()}")


def trace_so_far(daemon):
    try:
        return [json.loads(line) for line in daemon.trace.read_text().splitlines() if line.endswith("}")]
    except (OSError, ValueError):
        return []


class Traffic:
    """The applications: a sends to b every 0.2 s; b counts what it gets."""

    def __init__(self, daemon, a, b):
        self.stop = threading.Event()
        self.received = 0
        self.sent = 0
        self.errors = []
        self.threads = [threading.Thread(target=self._send, args=(daemon, a), daemon=True),
                        threading.Thread(target=self._receive, args=(daemon, b), daemon=True)]
        for thread in self.threads:
            thread.start()

    def _send(self, daemon, a):
        try:
            with Link.open(a, runtime_dir=daemon.runtime) as link:
                while not self.stop.is_set():
                    link.send(b"ping %d" % self.sent, dst=2)
                    self.sent += 1
                    time.sleep(0.2)
        except Exception as exc:  # the test fails on it below
            self.errors.append(repr(exc))

    def _receive(self, daemon, b):
        try:
            with Link.open(b, runtime_dir=daemon.runtime) as link:
                while not self.stop.is_set():
                    if link.recv(timeout=0.2) is not None:
                        self.received += 1
        except Exception as exc:
            self.errors.append(repr(exc))

    def close(self):
        self.stop.set()
        for thread in self.threads:
            thread.join(30)


def counted(events, link, start, end):
    """The trace's tx and rx of ``link`` between two line indexes: rx lines are the frames the link's
    modem handed up (a simulated modem's own MAC/ACK frames carry another kind and are not counted)."""
    lines = [e for e in events[start:end] if e.get("link") == link]
    tx = sum(e["ev"] == "tx" for e in lines)
    rx = sum(e["ev"] == "rx" and (e.get("kind") is None or e["kind"].startswith("recv")) for e in lines)
    return tx, rx


def test_a_swap_to_an_emulated_modem_and_back_keeps_one_account_per_link(tmp_path, daemon_of):
    a, b, ea, eb = unique("sa"), unique("sb"), unique("ea"), unique("eb")
    simulated, real = scenes(tmp_path, a, b, ea, eb)
    daemon = daemon_of(simulated, [a, b, ea, eb])
    traffic = None
    try:
        traffic = Traffic(daemon, a, b)
        wait(lambda: traffic.received >= 10, "10 frames through the simulated links", daemon)
        tx_before = daemon.link_status(a)["tx_packets"]
        daemon.reload(real)
        after_first = daemon.link_status(a)
        assert after_first["backend"] == "evologics" and after_first["tx_packets"] >= tx_before  # kept
        assert after_first["since_s"] > 0
        wait(lambda: sum(e.get("link") == a and e["ev"] == "tx" and "pkt" not in e for e in trace_so_far(daemon))
             >= 30, "30 frames through the driver and the emulated modems", daemon)
        tx_real = daemon.link_status(a)["tx_packets"]
        daemon.reload(simulated)  # the file says "all simulated" from now on
        assert daemon.link_status(a)["tx_packets"] >= tx_real
        received = traffic.received
        wait(lambda: traffic.received >= received + 10, "10 more frames through the simulated links again", daemon)
        final = daemon.link_status(a)
        traffic.close()
        assert not traffic.errors  # the application never noticed
        daemon.stop()
    finally:
        if traffic is not None:
            traffic.close()

    events = daemon.trace_events()
    summary = json.loads(daemon.summary.read_text())
    reloads = [i for i, e in enumerate(events) if e["ev"] == "reload"]
    assert len(reloads) == 2 and events[0]["ev"] == "run" and events[0]["scene_view"]["links"][a]["backend"] == "sim"
    first, second = (events[i] for i in reloads)
    assert first["changes"][a]["backend"] == ["sim", "evologics"] and first["changes"][ea] == {"added": True}
    assert second["changes"][b]["backend"] == ["evologics", "sim"] and second["changes"][eb] == {"removed": True}
    assert first["scene_view"]["links"][a]["backend"] == "evologics" and first["scene_hash"] != events[0]["scene_hash"]
    assert second["scene_hash"] == events[0]["scene_hash"]  # the same scene as at the start

    links = {entry["id"]: entry for entry in summary["links"]}
    assert set(links) == {a, b, ea, eb}  # every link that existed during the run, the removed ones too
    bounds = [0, reloads[0], reloads[1], len(events)]
    for link in (a, b):
        segments = links[link]["segments"]
        assert [s["backend"] for s in segments] == ["sim", "evologics", "sim"]
        assert [s["start_s"] for s in segments] == [0.0, first["t"], second["t"]]
        assert [s["end_s"] for s in segments] == [first["t"], second["t"], summary["sim_time_s"]]
        for k, segment in enumerate(segments):
            assert (segment["tx_packets"], segment["rx_packets"]) == counted(events, link, bounds[k], bounds[k + 1])
        for key in ("tx_packets", "rx_packets"):
            assert links[link][key] == sum(s[key] for s in segments)
        assert links[link]["fifo_drops"] == sum(s["drops"] for s in segments)
    assert links[a]["tx_packets"] >= final["tx_packets"] >= tx_real >= tx_before > 0
    assert links[b]["segments"][1]["rx_packets"] > 0  # frames did reach b through the emulated modems
    for link in (ea, eb):
        [segment] = links[link]["segments"]
        assert segment["backend"] == "sim" and (segment["start_s"], segment["end_s"]) == (first["t"], second["t"])
    assert summary["wall_time_s"] >= summary["sim_time_s"] > 0

    # fit from the trace alone: a and b were real between the reloads, whatever the file says now
    real_tx = [e for e in events[reloads[0]:reloads[1]] if e.get("link") == a and e["ev"] == "tx"]
    real_rx = [e for e in events[reloads[0]:reloads[1]] if e.get("link") == b and e["ev"] == "rx"]
    result = run_fit(str(daemon.trace), model="logistic")
    assert len(result.data.frames) + result.data.excluded.get("no pose", 0) == len(real_tx)
    assert sum(o.delivered for o in result.data.frames) == len(real_rx)
    assert {(o.src, o.dst) for o in result.data.frames} == {(a, b)}
    cli = subprocess.run([sys.executable, "-m", "hilgate", "fit", str(daemon.trace), "--model", "logistic"],
                         capture_output=True, text=True, timeout=120)
    assert cli.returncode == 0 and "Traceback" not in cli.stderr, cli.stderr

    # report marks the period a and b were real on their flow's timeline
    trace = load_trace(str(daemon.trace))
    assert trace.real_periods(a) == [(first["t"], second["t"], "evologics")]
    out = tmp_path / "report"
    cli = subprocess.run([sys.executable, "-m", "hilgate", "report", str(daemon.trace), "--out", str(out)],
                         capture_output=True, text=True, timeout=120)
    assert cli.returncode == 0, cli.stderr
    assert "timeline.png" in os.listdir(out)


def test_a_link_removed_and_added_again_keeps_its_account(daemon_of):
    a, b = unique("ra"), unique("rb")
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{va: {{pose: {{static: [0, 0, 0]}}}}, vb: {{pose: {{static: [150, 0, 0]}}}}}}
links:
  {a}: {{vehicle: va, address: 1, bitrate_bps: 2000, gli: [socket]}}
  {b}: {{vehicle: vb, address: 2, bitrate_bps: 2000, gli: [socket]}}
"""
    daemon = daemon_of(scene, [a, b])
    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        la.send(b"one", dst=2)
        assert lb.recv(timeout=30).data == b"one"
    daemon.reload(scene.replace(f"  {b}: {{vehicle: vb, address: 2, bitrate_bps: 2000, gli: [socket]}}\n", ""))
    assert [link["id"] for link in daemon.status()["links"]] == [a]
    daemon.reload(scene)
    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        la.send(b"two", dst=2)
        assert lb.recv(timeout=30).data == b"two"
    status = {link["id"]: link for link in daemon.status()["links"]}
    assert status[b]["rx_packets"] == 2 and status[a]["since_s"] == 0.0 < status[b]["since_s"]
    table = subprocess.run([sys.executable, "-m", "hilgate", "status", "--runtime-dir", daemon.runtime],
                           capture_output=True, text=True, timeout=60)
    header = next(line for line in table.stdout.splitlines() if line.startswith("link "))
    assert "since s" in header
    daemon.stop()
    events = daemon.trace_events()
    first, second = (e for e in events if e["ev"] == "reload")
    assert first["changes"] == {b: {"removed": True}} and second["changes"] == {b: {"added": True}}
    summary = json.loads(daemon.summary.read_text())
    [entry] = [link for link in summary["links"] if link["id"] == b]
    assert entry["rx_packets"] == 2 and [s["rx_packets"] for s in entry["segments"]] == [1, 1]
    assert [(s["start_s"], s["end_s"]) for s in entry["segments"]] == [(0.0, first["t"]),
                                                                       (second["t"], summary["sim_time_s"])]
