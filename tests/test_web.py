"""Issue 29: the operator's view in a browser, live from the daemon (``hilgate run --web``) and from a trace
(``hilgate view TRACE``).

The browser tests drive Debian's chromium (headless, through chromedriver: ``browser_kit.py``) against
the real daemon: the page loads, shows the scene's vehicles and links, a frame an application sends is
drawn in flight and then with its fate, a link a reload swaps to a real modem changes its badge, a
killed host of a network shows down, and the trace player reaches the end of a trace with the counters
``hilgate report`` finds.  The door's access rules are checked with a plain WebSocket client."""

from __future__ import annotations

import asyncio
import csv
import json
import signal
import socket
import subprocess
import sys
import uuid
from collections import Counter
from pathlib import Path

import pytest

from browser_kit import HANG_GUARD_S, browser  # noqa: F401  (the fixture)
from daemon_kit import Daemon, free_port, hilgate, unique
from hilgate.client import Link
from hilgate.gli.token import proof
from hilgate.report.causes import RECEIVED, words
from hilgate.report.tracedata import load_trace
from hilgate.web.picture import Flight, frame_view, scene_message
from hilgate.web.replay import Replay

REPO = Path(__file__).resolve().parent.parent
pytest.importorskip("tornado", reason="the web view needs tornado: pip install -e '.[test]'")


def page_address(daemon: Daemon) -> str:
    """What ``hilgate view`` prints for a running daemon: its address with the token."""
    result = hilgate("view", "--runtime-dir", daemon.runtime)
    assert result.returncode == 0, result.stderr
    url = result.stdout.strip()
    assert url.startswith("http://127.0.0.1:") and "#token=" in url, url
    return url


def badge(browser, link: str) -> str:  # noqa: F811
    return browser.js(f"const b = document.querySelector('tr[data-link=\"{link}\"] .badge'); return b && b.dataset.kind;")


# -- the live view --------------------------------------------------------------------------------

def live_scenes(tmp_path, a, b, c, ea, eb):
    head = """\
name: lab-tank-sea-trial
seed: 5
channels: {ac: {speed_mps: 1500}}
vehicles:
  topside: {pose: {static: [0, 0, 2]}}
  auv: {pose: {static: [6000, 2000, 40]}}
  glider: {pose: {path: {start: [2500, -2500, 15], legs: [{to: [2500, 2500, 15], speed_mps: 40},
                                                           {to: [2500, -2500, 15], speed_mps: 40}], loop: true}}}
links:
"""
    modem = "packet: vl2b, bitrate_bps: 2000, gli: [socket]"
    glider = f"  {c}: {{vehicle: glider, address: 3, {modem}, range_m: [0, 5000]}}\n"
    flows = f"flows:\n  - {{from: {c}, to: '*', size_bytes: 30, interval_s: 1.5}}\n"
    simulated = head + f"""\
  {a}: {{vehicle: topside, address: 1, {modem}, error: {{unit: packet, expr: "d / 8000"}}}}
  {b}: {{vehicle: auv, address: 2, {modem}}}
""" + glider + flows
    pa, pb = tmp_path / "modem_a", tmp_path / "modem_b"
    real = head + f"""\
  {ea}: {{vehicle: topside, address: 1, {modem}, emulate: {{protocol: evologics, pty: {pa}}}}}
  {eb}: {{vehicle: auv, address: 2, {modem}, emulate: {{protocol: evologics, pty: {pb}}}}}
  {a}: {{vehicle: topside, backend: evologics, port: {pa}, ack: false, address: 1, packet: vl2b, gli: [socket]}}
  {b}: {{vehicle: auv, backend: evologics, port: {pb}, ack: false, address: 2, packet: vl2b, gli: [socket]}}
""" + glider + flows
    return simulated, real


def test_the_live_view_draws_the_scene_a_frame_in_flight_and_its_fate_and_a_swapped_badge(tmp_path, browser, daemon_of):  # noqa: F811
    a, b, c, ea, eb = (unique(p) for p in ("wa", "wb", "wc", "we", "wf"))
    simulated, real = live_scenes(tmp_path, a, b, c, ea, eb)
    daemon = daemon_of(simulated, [a, b, c, ea, eb], "--web", "0")
    alive = lambda: daemon.process.poll() is None or pytest.fail(daemon.output())  # noqa: E731
    url = page_address(daemon)
    assert "web view on http://127.0.0.1:" in daemon.output() and "#token=" not in daemon.output()
    browser.open(url)
    browser.wait("v.authed && v.scene && v.state", "the daemon's scene", alive=alive)
    assert browser.js("return location.hash") == ""  # the token left the address bar
    assert sorted(browser.view("v.state.vehicles.map(x => x.name)")) == ["auv", "glider", "topside"]
    browser.wait("document.querySelectorAll('#top [data-vehicle]').length == 3", "the vehicles drawn")
    legend = browser.js("return [...document.querySelectorAll('#legend [data-fate]')].map(s => s.textContent)")
    assert legend[:3] == [RECEIVED.words, words("col"), words("mult")]  # the report's words (report/causes.py)
    assert browser.view("v.scene.mode") == "live"
    for link in (a, b, c):
        assert badge(browser, link) == "sim"
    assert browser.view(f"Object.keys(v.scene.links).sort()") == sorted([a, b, c])
    # the range ring of the glider's modem (5 km) is drawn, the unbounded ones are not
    browser.wait(f"document.querySelectorAll('#top [data-ring]').length == 1", "the glider's range ring")

    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        la.send(b"hello from the topside", dst=2)
        states = browser.wait(f"[...v.seen.values()].filter(e => e.src == '{a}').map(e => e.states)"
                              f".find(s => s.includes('rx'))", "the frame's fate", alive=alive)
        # drawn on its way (4.2 s of water to b), then delivered there (vl2b has no address on air: the
        # glider hears it too, and may lose it to errors)
        assert states[0] == "flight" and "rx" in states
        assert lb.recv(timeout=HANG_GUARD_S).data == b"hello from the topside"
        tx = browser.view(f"v.state.links.find(l => l.id == '{a}').tx")
        assert tx >= 1
        # the glider's broadcasts: the topside's modem loses some to errors (its error model: d / 8000)
        browser.wait("[...v.seen.values()].some(e => e.states.includes('prop'))", "a frame lost to errors",
                     alive=alive)

    daemon.reload(real)
    browser.wait(f"(() => {{ const b = document.querySelector('tr[data-link=\"{a}\"] .badge');"
                 f" return b && b.dataset.kind == 'real'; }})()", "link a's badge after the swap", alive=alive)
    assert badge(browser, b) == "real" and badge(browser, ea) == "emulated" and badge(browser, c) == "sim"
    assert "evologics" in browser.js(f"return document.querySelector('tr[data-link=\"{a}\"] .badge').textContent")
    with Link.open(a, runtime_dir=daemon.runtime) as la, Link.open(b, runtime_dir=daemon.runtime) as lb:
        la.send(b"over the real modems", dst=2)
        assert lb.recv(timeout=HANG_GUARD_S).data == b"over the real modems"
        browser.wait(f"[...v.seen.values()].some(e => e.src == '{ea}' && e.states.includes('rx'))",
                     "the emulated modem's frame delivered", alive=alive)
        la.send(b"one more, for the picture", dst=2)
        browser.wait(f"[...document.querySelectorAll('#flight .wave')].length >= 2 &&"
                     f" document.querySelectorAll('#flight .flight').length >= 1", "frames in flight", alive=alive)
        browser.keep(tmp_path, "live-swapped")  # (the README's screenshot is test_web_operator.py's, at 1280×800)
        lb.recv(timeout=HANG_GUARD_S)
    status = daemon.status()
    assert status["web"]["pages"] == 1 and status["web"]["url"] in url
    # the same run, played from its trace: the link was simulated at first and real at the end
    trace = load_trace(str(daemon.trace))
    replay = Replay(trace, trace.scenes)
    assert {l["id"]: l["kind"] for l in replay.state(0.0)["links"]}[a] == "sim"
    assert {l["id"]: l["kind"] for l in replay.state(replay.end)["links"]}[a] == "real"


def test_a_killed_host_shows_down(tmp_path, browser):  # noqa: F811
    prefix = f"hilgate-test-{uuid.uuid4().hex[:8]}"
    a, b = unique("ka"), unique("kb")
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
zenoh: {{prefix: {prefix}, insecure: true, lease_s: 5}}
vehicles: {{va: {{pose: {{static: [0, 0, 0]}}}}, vb: {{pose: {{static: [300, 0, 0]}}}}}}
links:
  {a}: {{vehicle: va, host: A, address: 1, bitrate_bps: 1000, gli: [socket]}}
  {b}: {{vehicle: vb, host: B, address: 2, bitrate_bps: 1000, gli: [socket]}}
"""
    ports = [free_port(), free_port()]
    (tmp_path / "A").mkdir()
    (tmp_path / "B").mkdir()
    host_a = Daemon(tmp_path / "A", scene, [a], "--host", "A", "--zenoh-listen", f"tcp/127.0.0.1:{ports[0]}",
                    "--web", "0")
    host_b = None
    try:
        host_a.wait_for("READY=1")
        host_b = Daemon(tmp_path / "B", scene, [b], "--host", "B", "--zenoh-listen", f"tcp/127.0.0.1:{ports[1]}",
                        "--zenoh-connect", f"tcp/127.0.0.1:{ports[0]}")
        host_b.wait_for("READY=1")
        browser.open(page_address(host_a))
        row = "(() => { const r = document.querySelector('tr[data-host=\"B\"] td.state'); return r && r.textContent; })()"
        assert browser.wait(f"{row} == 'up'", "host B up") is True
        assert badge(browser, b) == "remote" and badge(browser, a) == "sim"
        host_b.process.send_signal(signal.SIGKILL)
        host_b.process.wait()
        browser.wait(f"{row} == 'down'", "host B down after its daemon was killed")
        browser.wait("[...document.querySelectorAll('#log-list li[data-kind=\"host\"][data-level=\"error\"]')]"
                     ".some(li => li.textContent.includes('host B lost'))", "host B lost, in the event log")
        browser.wait(f"(() => {{ const r = document.querySelector('tr[data-link=\"{b}\"] td.state');"
                     f" return r && r.textContent == 'down'; }})()", "B's link down")
        assert browser.js("return document.querySelector('tr[data-host=\"B\"] td.state').className").endswith("down")
    finally:
        host_a.close()
        if host_b is not None:
            host_b.close()


# -- the trace player ------------------------------------------------------------------------------

PLAYER_SCENE = """\
name: player
seed: 11
duration_s: 90
channels: {ac: {speed_mps: 1500}}
vehicles:
  a: {pose: {static: [0, 0, 5]}}
  b: {pose: {path: {start: [200, 0, 5], legs: [{to: [900, 300, 20], speed_mps: 20}, {to: [200, 0, 5], speed_mps: 20}], loop: true}}}
  c: {pose: {static: [400, -400, 10]}}
links:
  la: {vehicle: a, address: 1, bitrate_bps: 1000, error: {unit: packet, expr: "d / 2000"}}
  lb: {vehicle: b, address: 2, bitrate_bps: 1000, error: {unit: packet, expr: "d / 2000"}, range_m: [0, 800]}
  lc: {vehicle: c, address: 3, bitrate_bps: 2000, fifo_bytes: 60}
flows:
  - {from: la, to: lb, size_bytes: 40, interval_s: 0.7}
  - {from: lb, to: la, size_bytes: 32, interval_s: 0.9, poisson: true}
  - {from: lc, to: "*", size_bytes: 50, interval_s: 0.6, poisson: true}
"""


def report_counts(trace_path: Path, out: Path) -> dict[str, dict]:
    """Per flow, what ``hilgate report`` finds: frames sent (its reader's transmissions), received and lost by
    cause (from the packets.csv it writes)."""
    result = hilgate("report", str(trace_path), "--out", str(out), "--csv")
    assert result.returncode == 0, result.stderr
    counts: dict[str, dict] = {}
    with open(out / "packets.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            flow = counts.setdefault(f"{row['src']} → {row['dst']}", {"received": 0, "lost": Counter()})
            if row["outcome"] == "rx":
                flow["received"] += 1
            else:
                flow["lost"][row["cause"]] += 1
    trace = load_trace(str(trace_path))
    for packet in trace.packets.values():
        flow = counts.setdefault(f"{packet.src} → {packet.dst}", {"received": 0, "lost": Counter()})
        flow["sent"] = flow.get("sent", 0) + len(packet.t_tx)
    return {key: {"sent": v.get("sent", 0), "received": v["received"], "lost": dict(v["lost"])}
            for key, v in counts.items()}


def page_flows(browser) -> dict[str, dict]:  # noqa: F811
    rows = browser.js("""return [...document.querySelectorAll('#flows tbody tr')].map(r => [r.dataset.flow,
        r.querySelector('.sent').textContent, r.querySelector('.received').textContent, r.querySelector('.lost').dataset.lost]);""")
    return {flow: {"sent": int(sent), "received": int(received), "lost": json.loads(lost)}
            for flow, sent, received, lost in rows}


def test_the_trace_player_reaches_the_end_with_the_counters_of_hilgate_report(tmp_path, browser):  # noqa: F811
    from selenium.webdriver.support.ui import Select

    scene = tmp_path / "player.yaml"
    scene.write_text(PLAYER_SCENE)
    trace = tmp_path / "trace.jsonl"
    result = hilgate("sim", str(scene), "--trace", str(trace), "-q")
    assert result.returncode == 0, result.stderr
    expected = report_counts(trace, tmp_path / "report")
    assert any(f["lost"].get("fifo") for f in expected.values()) and any(f["lost"].get("prop") for f in expected.values())

    refused = hilgate("view", str(trace))  # a hilgate sim trace names no scene
    assert refused.returncode == 2 and "--scene FILE" in refused.stderr and "Traceback" not in refused.stderr
    viewer = subprocess.Popen([sys.executable, "-m", "hilgate", "view", str(trace), "--scene", str(scene)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = viewer.stdout.readline()
        assert line.startswith(f"playing {trace}: ") and "#token=" in line, line + viewer.stderr.read()
        browser.open(line.split(" at ", 1)[1].split(" ")[0])
        browser.wait("v.authed && v.state && v.scene", "the trace's first picture")
        assert browser.view("v.scene.mode") == "replay" and browser.js("return document.getElementById('player').hidden") is False
        speeds = browser.js("return [...document.querySelectorAll('#speed option')].map(o => Number(o.value))")
        assert min(speeds) == 0.1 and max(speeds) == 100
        at_start = page_flows(browser)  # (frames sent at t = 0 exactly are sent at the start)
        assert browser.view("v.state.t") == 0 and all(f["sent"] <= 1 and f["received"] == 0 for f in at_start.values())
        Select(browser.driver.find_element("id", "speed")).select_by_value("100")
        browser.wait("v.state.speed == 100", "the speed taken")
        browser.driver.find_element("id", "play").click()
        browser.wait("v.state.playing || v.state.t > 0", "the player started")
        end = browser.wait("!v.state.playing && v.state.t == v.state.end && v.state.end", "the end of the trace")
        assert end == pytest.approx(load_trace(str(trace)).end, abs=1e-6)
        assert page_flows(browser) == expected
        assert browser.js("return document.getElementById('play').textContent").endswith("play")
        # the slider seeks anywhere, backwards too: at the start nothing was sent yet
        browser.js("const s = document.getElementById('slider'); s.value = 0; s.dispatchEvent(new Event('input'));")
        browser.wait("v.state.t == 0", "the player back at the start")
        assert page_flows(browser) == at_start
    finally:
        viewer.send_signal(signal.SIGINT)
        assert viewer.wait(30) == 0
        assert "Traceback" not in viewer.stderr.read()


# -- the door's rules, with a plain WebSocket client ----------------------------------------------

async def _session(url: str, messages: list, origin: str | None = None, answer=None, commands=(), count: int = 3):
    from tornado.httpclient import HTTPRequest
    from tornado.websocket import websocket_connect

    headers = {"Origin": origin} if origin else {}
    connection = await asyncio.wait_for(websocket_connect(HTTPRequest(url, headers=headers)), HANG_GUARD_S)
    try:
        hello = json.loads(await asyncio.wait_for(connection.read_message(), HANG_GUARD_S))
        messages.append(hello)
        if answer is not None:
            await connection.write_message(json.dumps({"class": "AUTH", "proof": answer(hello["nonce"])}))
        for command in commands:
            await connection.write_message(json.dumps(command))
        while len(messages) < count:
            text = await asyncio.wait_for(connection.read_message(), HANG_GUARD_S)
            if text is None:
                messages.append({"closed": connection.close_code})
                return
            messages.append(json.loads(text))
    finally:
        connection.close()


@pytest.fixture
def player(tmp_path):
    """``hilgate view`` of a short trace, its token from a file (as a lab would give its group's)."""
    scene = tmp_path / "player.yaml"
    scene.write_text(PLAYER_SCENE.replace("duration_s: 90", "duration_s: 10"))
    trace = tmp_path / "trace.jsonl"
    assert hilgate("sim", str(scene), "--trace", str(trace), "-q").returncode == 0
    token = tmp_path / "token"
    token.write_text("t" * 40 + "\n")
    viewer = subprocess.Popen([sys.executable, "-m", "hilgate", "view", str(trace), "--scene", str(scene),
                               "--token-file", str(token)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = viewer.stdout.readline()
    try:
        assert "#token=" + "t" * 40 in line, line + viewer.stderr.read()
        yield line.split(" at ", 1)[1].split("#")[0], b"t" * 40
    finally:
        viewer.send_signal(signal.SIGTERM)
        viewer.wait(30)


def test_a_page_without_the_token_gets_nothing_and_pages_of_other_sites_are_refused(player):
    from tornado.httpclient import HTTPClientError

    base, token = player
    ws = base.replace("http://", "ws://") + "ws"
    wrong: list = []
    asyncio.run(_session(ws, wrong, answer=lambda nonce: proof(b"x" * 40, bytes.fromhex(nonce))))
    assert wrong[0]["class"] == "HELLO" and len(wrong[0]["nonce"]) == 64
    assert wrong[1]["class"] == "ERROR" and wrong[2] == {"closed": 1008}
    replayed: list = []  # a proof seen on the network answers no other connection's nonce
    asyncio.run(_session(ws, replayed, answer=lambda nonce: proof(token, bytes.fromhex(wrong[0]["nonce"]))))
    assert replayed[1]["class"] == "ERROR"
    right: list = []
    asyncio.run(_session(ws, right, answer=lambda nonce: proof(token, bytes.fromhex(nonce)),
                         commands=[{"class": "SPEED", "speed": 1000}, {"class": "SEEK", "t": "x"},
                                   {"class": "EVAL", "code": "1"}], count=8))
    kinds = [m.get("class") for m in right]
    assert kinds[:4] == ["HELLO", "WELCOME", "SCENE", "EVENTS"] and "STATE" in kinds
    errors = [m["error"] for m in right if m.get("class") == "ERROR"]
    assert errors == ["speed must be a number from 0.1 to 100", "t must be a number of seconds",
                      "unknown command 'EVAL' (PLAY, PAUSE, SPEED, SEEK)"]
    with pytest.raises(HTTPClientError) as refused:
        asyncio.run(_session(ws, [], origin="http://evil.example"))
    assert refused.value.code == 403


def test_a_page_opens_without_a_warning_about_the_ping_settings(tmp_path):
    """Tornado warned at the first page that ``websocket_ping_timeout`` 30 becomes 10 (issue 39)."""
    scene = tmp_path / "player.yaml"
    scene.write_text(PLAYER_SCENE.replace("duration_s: 90", "duration_s: 10"))
    trace = tmp_path / "trace.jsonl"
    assert hilgate("sim", str(scene), "--trace", str(trace), "-q").returncode == 0
    token = tmp_path / "token"
    token.write_text("p" * 40 + "\n")
    viewer = subprocess.Popen([sys.executable, "-m", "hilgate", "view", str(trace), "--scene", str(scene),
                               "--token-file", str(token)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = viewer.stdout.readline()
        ws = line.split(" at ", 1)[1].split("#")[0].replace("http://", "ws://") + "ws"
        opened: list = []
        asyncio.run(_session(ws, opened, answer=lambda nonce: proof(b"p" * 40, bytes.fromhex(nonce)), count=4))
        assert [m.get("class") for m in opened[:3]] == ["HELLO", "WELCOME", "SCENE"]
    finally:
        viewer.send_signal(signal.SIGTERM)
        _, errors = viewer.communicate(timeout=30)
    assert "websocket_ping" not in errors, errors


def test_the_page_is_served_with_its_own_scripts_only(player):
    from urllib.request import urlopen

    base, _ = player
    with urlopen(base, timeout=HANG_GUARD_S) as answer:
        page = answer.read().decode()
        assert "default-src 'self'" in answer.headers["Content-Security-Policy"]
        assert answer.headers["X-Frame-Options"] == "DENY"
    for resource in ("view.js", "view.css", "sha256.js", "favicon.svg"):
        assert f"/static/{resource}" in page or resource == "favicon.svg"
        with urlopen(base + "static/" + resource, timeout=HANG_GUARD_S) as answer:
            assert answer.status == 200
    assert "http" not in page.replace("http-equiv", "") or "://" not in page  # nothing from elsewhere


def test_the_web_door_refuses_a_port_in_use_and_a_daemon_without_it_says_so(tmp_path, daemon_of):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        a = unique("pu")
        scene = tmp_path / "s.yaml"
        scene.write_text(f"channels: {{ac: {{speed_mps: 1500}}}}\nvehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}\nlinks:\n  {a}: {{vehicle: v, address: 1, gli: [socket]}}\n")
        result = hilgate("run", str(scene), "--runtime-dir", str(tmp_path / "rt"), "--web", str(port), "--until", "1",
                         "--no-status-line")
        assert result.returncode == 1 and "Address already in use" in result.stderr
        assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1
    bad = hilgate("run", str(scene), "--web", "70000")
    assert bad.returncode == 2 and "'70000' is not [ADDR:]PORT" in bad.stderr
    daemon = daemon_of(scene.read_text(), [a])
    answer = hilgate("view", "--runtime-dir", daemon.runtime)
    assert answer.returncode == 1 and "serves no web view: start it with --web" in answer.stderr


# -- the picture, without a browser -----------------------------------------------------------------

def test_a_frame_is_drawn_from_its_transmission_until_its_wave_passed_and_its_fates_linger():
    links = scene_message({"channels": {"ac": {"speed_mps": 1500, "min_delay_s": 0}},
                           "vehicles": {"v": {"source": "static"}},
                           "links": {"a": {"vehicle": "v", "backend": "sim", "tx_channel": "ac",
                                           "params": {"range_m": [0, 3000], "bitrate_bps": 1000}}}}, "live")["links"]
    assert links["a"]["kind"] == "sim" and links["a"]["range_m"] == [0.0, 3000.0]
    flight = Flight(links)
    flight.frame("enq", 0.0, "a", 7, "a", "b", 25, None)
    assert flight.visible(0.0) == []  # queued, not on air yet
    flight.frame("tx", 1.0, "a", 7, "a", "b", 25, None)
    reach = 3000 / 1500 + 25 * 8 / 1000
    [drawn] = flight.visible(1.5)
    assert drawn == {"id": "7", "src": "a", "dst": "b", "size": 25, "tx": 1.0, "reach_s": reach, "out": []}
    flight.frame("rx", 2.2, "b", 7, "a", "b", 25, None)
    flight.frame("err", 2.3, "c", 7, "a", "b", 25, "col")
    assert flight.visible(2.25)[0]["out"] == [["b", 2.2, "rx", None]]
    assert flight.visible(4.0)[0]["out"] == [["b", 2.2, "rx", None], ["c", 2.3, "err", "col"]]
    assert flight.visible(1.0 + reach + 2.0 + 0.5) == []  # wave gone, fates faded
    assert flight.errors_of("c") == [[2.3, "col", "from a"]]
    for i in range(10):
        flight.line({"t": 3.0 + i, "ev": "drop", "link": "a", "src": "app", "size": 3, "cause": "no_reader"})
    assert len(flight.errors_of("a")) == 5 and flight.errors_of("a")[-1][1] == "no_reader"
    flight.visible(100.0)
    assert not flight.frames  # forgotten once nothing of them can be drawn
    assert frame_view(1, "a", "b", 3, [5.0], [], 4.0, 1.0, 2.0) is None  # not sent yet at t=4


def test_a_hostile_scene_view_becomes_a_scene_the_page_can_draw():
    hostile = {"name": {"x": 1}, "channels": {"ac": {"speed_mps": -3, "min_delay_s": "soon"}}, "vehicles": [1, 2],
               "links": {"a": {"vehicle": "<img src=x onerror=alert(1)>", "backend": 7, "tx_channel": "ac",
                               "params": {"range_m": [None, float("inf")], "bitrate_bps": float("nan")},
                               "emulate": {"protocol": "evologics"}}, "b": "not a link"}}
    message = scene_message(hostile, "replay")
    link = message["links"]["a"]
    assert link["kind"] == "emulated" and link["speed_mps"] == 1500.0 and link["min_delay_s"] == 0.0
    assert link["range_m"] == [0.0, None] and link["bitrate_bps"] is None and "b" not in message["links"]
    json.dumps(message, allow_nan=False)  # strict JSON: what the page gets parses


def test_a_strange_trace_plays_or_is_refused_in_one_line(tmp_path):
    """Lines a reader lets through but no daemon writes (frames judged before they were sent, a pose
    unknown, a link no scene names, a scene of odd values) play; a bad line is one line naming it."""
    view = {"name": "odd", "channels": {"ac": {"speed_mps": 0}}, "vehicles": {"v": {}},
            "links": {"a": {"vehicle": "v", "backend": "sim", "params": {"range_m": [5, 1]}}}}
    lines = [{"t": 0.0, "ev": "run", "run": "r1", "scene_view": view},
             {"t": 1.0, "ev": "pose", "vehicle": "v", "position": None},
             {"t": 2.0, "ev": "pose", "vehicle": "v", "position": [1, 2, 3]},
             {"t": 3.0, "ev": "rx", "link": "ghost", "pkt": "x", "src": "a", "dst": "*", "size": 3},
             {"t": 2.5, "ev": "tx", "link": "a", "pkt": "x", "src": "a", "dst": "*", "size": 3},
             {"t": 4.0, "ev": "host", "host": "B", "state": "down"},
             {"t": 5.0, "ev": "drop", "link": "a", "pkt": 9, "src": "a", "dst": "b", "size": 1e3 and 1000,
              "cause": "fifo", "fifo_bytes": 0}]
    trace = tmp_path / "odd.jsonl"
    trace.write_text("".join(json.dumps(line) + "\n" for line in lines))
    loaded = load_trace(str(trace))
    replay = Replay(loaded, loaded.scenes)
    for t in (-5.0, 0.0, 1.5, 2.7, 3.0, 4.5, 5.0, 1e9):
        state = replay.state(t, 100.0, True)
        json.dumps(state, allow_nan=False)
    assert replay.state(5.0)["hosts"] == [{"host": "B", "state": "down"}]
    assert [f["id"] for f in replay.state(3.0)["frames"]] == ["x"]
    trace.write_text(trace.read_text() + '{"t": 6, "ev": "host", "host": "B", "state": "sideways"}\n')
    result = hilgate("view", str(trace))
    assert result.returncode == 1 and "odd.jsonl:8: 'state' must be" in result.stderr
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1
