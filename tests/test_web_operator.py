"""Issue 41: an operator's view, the live page an experiment is run from, checked in Chromium at 1280×800.

The fixes (each of these failed on the page before): the demo's range rings of 80 000–320 000 px were
drawn dashed and stalled the browser; frames in flight were almost never drawn (an RF frame's flight is
microseconds, shorter than the 100 ms between pictures); the page was wider than 1280 px and a replay
taller than 800; vehicles close together or at one depth printed their labels over each other; the
tables said ``col`` and ``prop`` where the legend said "collided" and "lost to errors", and a zero loss
was a red "0"; at 100× the player drew no fate.  Then what operators expect: a chart with a grid, a
scale bar and north that zooms and pans, trails and headings, an event log with severities, a frame or
a link inspected by a click, a pair of modems hovered for distance, delay and PER, per-link rates, the
player stepping from event to event on a time axis and taking the keyboard, acknowledgements on request.
A silent pose source flagged stale in the page, ``hilgate status`` and the log is in test_stale_poses.py.

Each test keeps the page's screenshot and DOM as artefacts (its tmp_path, or ``HILGATE_ARTEFACTS``);
``HILGATE_WRITE_FIGURES=1`` also writes docs/live-view.md's figures.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from browser_kit import browser  # noqa: F401  (the fixture)
from daemon_kit import hilgate, unique
from hilgate.client import Link

REPO = Path(__file__).resolve().parent.parent
FIGURES = REPO / "docs" / "figures"
pytest.importorskip("tornado", reason="the web view needs tornado: pip install -e '.[test]'")

RED = "rgb(164, 22, 26)"
CODES = r"(^|, )(col|mult|prop|range|fifo|no_reader|not_a_frame|no_pose|band|modulation) \d"


def figure(shot: str, name: str) -> None:
    if os.environ.get("HILGATE_WRITE_FIGURES"):
        shutil.copyfile(shot, FIGURES / name)


def page_address(daemon) -> str:
    result = hilgate("view", "--runtime-dir", daemon.runtime)
    assert result.returncode == 0, result.stderr
    return result.stdout.strip()


def demo_scene(prefix: str, extra_vehicles: bool = True) -> tuple[str, dict[str, str]]:
    """scenes/demo.yaml with its links renamed (a link id is one daemon's per machine) and on the GLI's
    sockets only (the POSIX-queue budget is shared by every run here); with a diver and a buoy beside the
    BlueROV, at its depth, for labels that must not collide."""
    data = yaml.safe_load((REPO / "scenes" / "demo.yaml").read_text())
    names = {old: f"{prefix}{old}" for old in data["links"]}
    data["links"] = {names[old]: {**link, "gli": ["socket"]} for old, link in data["links"].items()}
    for flow in data["flows"]:
        flow["from"] = names[flow["from"]]
        flow["to"] = names.get(flow["to"], flow["to"])
    if extra_vehicles:
        data["vehicles"]["diver"] = {"pose": {"static": [0.3, 0.25, 1]}}
        data["vehicles"]["buoy"] = {"pose": {"static": [-0.25, 0.3, 1]}}
    return yaml.safe_dump(data, sort_keys=False), names


def overlaps(browser, selector: str) -> list:  # noqa: F811
    """Pairs of the page's elements matching ``selector`` whose boxes overlap (by more than half a pixel)."""
    return browser.js(f"""
        const boxes = [...document.querySelectorAll({json.dumps(selector)})]
          .filter(t => !/^[\\d.]+ k?m$/.test(t.textContent) && t.textContent != 'depth (m)')
          .map(t => [t.textContent, t.getBoundingClientRect()]).filter(([, r]) => r.width > 0);
        const out = [];
        for (let i = 0; i < boxes.length; i++) for (let j = i + 1; j < boxes.length; j++) {{
          const [a, r] = boxes[i], [b, s] = boxes[j];
          if (r.left + 0.5 < s.right && s.left + 0.5 < r.right && r.top + 0.5 < s.bottom && s.top + 0.5 < r.bottom) out.push([a, b]);
        }}
        return out;""")


@pytest.fixture
def demo(tmp_path, daemon_of):
    prefix = unique("d") + "_"
    text, names = demo_scene(prefix)
    daemon = daemon_of(text, list(names.values()), "--web", "0")
    return daemon, names


def test_the_demo_at_1280x800_draws_every_frame_flying_and_fits_without_overlaps(demo, browser, tmp_path):  # noqa: F811
    daemon, names = demo
    alive = lambda: daemon.process.poll() is None or pytest.fail(daemon.output())  # noqa: E731
    browser.viewport(1280, 800)
    browser.open(page_address(daemon))
    browser.wait("v.authed && v.scene && v.state && document.querySelectorAll('#top [data-vehicle]').length == 5",
                 "the demo's five vehicles drawn", alive=alive)
    # every frame judged (not dropped at its sender, not without a pose) was drawn flying first: RF frames
    # fly for microseconds, far less than the 100 ms between two pictures (7 of 62 were drawn before)
    judged = ("[...v.seen.values()].filter(e => e.tx !== null && e.states.some(s => s != 'flight' && s != 'fifo'"
              " && s != 'no_pose'))")  # (tx null: sent before the page connected)
    browser.wait(f"{judged}.length >= 20", "20 frames judged", alive=alive)
    states = browser.view(f"{judged}.map(e => e.states)")
    assert all(s[0] == "flight" for s in states), [s for s in states if s[0] != "flight"]
    # the acoustic modems' rings are 80 000–320 000 px at this scale: none is drawn dashed so large
    radii = browser.view("[...document.querySelectorAll('#top circle[stroke-dasharray]')].map(c => c.r.baseVal.value)")
    assert all(r <= 2500 for r in radii), radii
    # 1280 px wide: no horizontal scrollbar, the last column on the screen
    assert browser.view("document.documentElement.scrollWidth") <= 1280
    assert browser.view("document.querySelector('#links th:last-child').getBoundingClientRect().right") <= 1280
    assert browser.view("document.documentElement.scrollHeight") <= 800
    # labels of vehicles 0.3 m apart at one depth do not print over each other, on the chart or the strip
    assert overlaps(browser, "#top text:not(.grid-label):not(.scale-label):not(.north-label)") == []
    assert overlaps(browser, "#depth text") == []
    # one vocabulary: the legend's words in the tables, a zero loss not in red
    browser.wait("[...document.querySelectorAll('#flows td.lost')].some(td => td.dataset.lost != '{}')",
                 "a flow's loss", alive=alive)
    lost = browser.view("[...document.querySelectorAll('#flows td.lost')].map(td => [td.textContent, td.dataset.lost,"
                        " getComputedStyle(td).color])")
    legend = browser.view("[...document.querySelectorAll('#legend [data-fate]')].map(s => s.textContent)")
    for text, counts, colour in lost:
        assert not re.search(CODES, text), text
        if json.loads(counts):
            assert any(word in text for word in legend), (text, legend)
        else:
            assert colour != RED, (text, colour)
    errors = browser.view("[...document.querySelectorAll('#links td.errors div')].map(d => d.textContent)")
    assert not any(re.search(r" s (col|mult|prop|fifo|no_reader) ", e) for e in errors), errors
    for td in browser.view("[...document.querySelectorAll('#links td.lost, #links td.drops')]"
                           ".filter(td => td.textContent == '0').map(td => getComputedStyle(td).color)"):
        assert td != RED
    figure(browser.keep(tmp_path, "demo-1280x800"), "web-live.png")


def test_a_wave_shorter_than_the_time_between_pictures_is_drawn(tmp_path, browser, daemon_of):  # noqa: F811
    """A modem alone on its channel: its 2 ms broadcasts reach nobody and are judged nowhere; each must
    still reach the page and be drawn (a real modem's frames, likewise, are a wave and nothing else)."""
    a, b = unique("sw"), unique("sx")
    scene = f"""\
channels: {{rf: {{speed_mps: 2.25e7}}, ac: {{speed_mps: 1500}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 1]}}}}, w: {{pose: {{static: [3, 0, 1]}}}}}}
links:
  {a}: {{vehicle: v, address: 1, channel: rf, bitrate_bps: 100000, range_m: [0, 6], gli: [socket]}}
  {b}: {{vehicle: w, address: 2, channel: ac, bitrate_bps: 1000, gli: [socket]}}
"""
    daemon = daemon_of(scene, [a, b], "--web", "0")
    browser.viewport(1280, 800)
    browser.open(page_address(daemon))
    browser.wait("v.authed && v.scene && v.state", "the scene")
    with Link.open(a, runtime_dir=daemon.runtime) as link:
        for i in range(5):
            link.send(b"x" * 25, dst=2)
            browser.wait(f"[...v.seen.values()].filter(e => e.states.includes('flight')).length >= {i + 1}",
                         f"broadcast {i + 1} drawn in flight")
    browser.keep(tmp_path, "short-wave")


def test_what_an_operator_expects_of_the_live_page(demo, browser, tmp_path):  # noqa: F811
    from selenium.webdriver.common.action_chains import ActionChains

    daemon, names = demo
    alive = lambda: daemon.process.poll() is None or pytest.fail(daemon.output())  # noqa: E731
    browser.viewport(1280, 800)
    browser.open(page_address(daemon))
    browser.wait("v.authed && v.scene && v.state && !!document.querySelector('#scale-bar')", "the chart", alive=alive)
    # a chart: grid, north, a scale bar that follows the zoom; pan by dragging, fit gives the framing back
    assert browser.view("document.querySelectorAll('#top .grid').length") >= 4
    assert browser.view("!!document.querySelector('#north')")
    scale = "(() => { const b = document.querySelector('#scale-bar'); return b.dataset.px / b.dataset.metres; })()"
    before = browser.view(scale)
    browser.driver.find_element("id", "zoom-in").click()
    browser.wait(f"Math.abs({scale} / {before} - 1.5) < 0.01", "the scale bar after zooming in")
    browser.js("document.getElementById('top').dispatchEvent(new WheelEvent('wheel', {deltaY: -200, clientX: 300, clientY: 300, bubbles: true, cancelable: true}))")
    browser.wait(f"{scale} > {before} * 1.5 * 1.2", "the scale bar after the wheel")
    cam = browser.view("v.map.cam")
    top = browser.driver.find_element("id", "top")
    ActionChains(browser.driver).move_to_element_with_offset(top, 0, 100).click_and_hold().move_by_offset(80, 40).release().perform()
    moved = browser.view("v.map.cam")
    assert moved["e"] < cam["e"] and moved["n"] > cam["n"] and not browser.view("v.map.auto")
    browser.driver.find_element("id", "fit").click()
    browser.wait("v.map.auto && document.querySelectorAll('#top [data-vehicle]').length == 5", "the framing back")
    # trails and headings of the vehicles that move
    auv = names["auv_ac"]
    browser.wait("!!document.querySelector('#top [data-trail=\"auv\"]') && !!document.querySelector('#top [data-vehicle=\"auv\"][data-heading]')",
                 "the AUV's trail and heading", alive=alive)
    # the event log: bursts of losses by cause, with a severity, and the alarm in the header
    browser.wait("!!document.querySelector('#log-list li[data-kind=\"burst\"][data-level=\"warning\"]')", "a burst of losses",
                 alive=alive)
    assert browser.view("!document.getElementById('alarms').hidden")
    # per-link rates over the last minutes
    browser.wait("[...document.querySelectorAll('#links td.rate svg')].some(s => Number(s.dataset.points) >= 2)",
                 "a link's rates", alive=alive)
    # click a link: the inspector shows its modem, counters, losses by cause and its chart
    browser.driver.find_element("css selector", f'tr[data-link="{auv}"] td.id').click()
    browser.wait(f"!!document.querySelector('#inspect[data-type=\"link\"][data-id=\"{auv}\"]') && !document.getElementById('inspect').hidden",
                 "the link inspected")
    keys = browser.view("[...document.querySelectorAll('#inspect dd')].map(d => d.dataset.key)")
    assert {"vehicle", "backend", "bitrate", "range", "counts", "causes"} <= set(keys)
    # click a frame: its size, source, destination, times, fate and cause
    clicked = browser.wait("""(() => { const f = [...document.querySelectorAll('#flight [data-frame] .fate, #flight [data-frame] .flight')][0];
        if (!f) return null; const o = {bubbles: true, clientX: 1, clientY: 1, pointerId: 1};
        f.dispatchEvent(new PointerEvent('pointerdown', o)); f.dispatchEvent(new PointerEvent('pointerup', o));
        return f.closest('[data-frame]').dataset.frame; })()""", "a frame to click", alive=alive)
    browser.wait(f"!!document.querySelector('#inspect[data-type=\"frame\"][data-id=\"{clicked}\"]')", "the frame inspected")
    frame = browser.view("Object.fromEntries([...document.querySelectorAll('#inspect dd')].map(d => [d.dataset.key, d.textContent]))")
    assert frame["size"].endswith("bytes") and frame["src"] and frame["dst"] and frame["tx"]
    shot = browser.keep(tmp_path, "inspect-frame")
    figure(shot, "web-inspect.png")
    browser.js("document.dispatchEvent(new KeyboardEvent('keydown', {key: 'Escape'}))")
    browser.wait("document.getElementById('inspect').hidden", "the inspector closed")
    # choose a vehicle, hover another: distance, delay, SNR/PER from the link budget
    for name, kind in (("bluerov", "pointerdown"), ("bluerov", "pointerup"), ("auv", "pointermove")):
        browser.js(f"""const g = document.querySelector('#top [data-vehicle="{name}"] circle:last-child');
            g.dispatchEvent(new PointerEvent('{kind}', {{bubbles: true, clientX: 1, clientY: 1, pointerId: 1}}));""")
    browser.wait("!document.getElementById('pair').hidden && v.pair", "the pair of modems")
    pair = browser.view("v.pair")
    spots = browser.view("Object.fromEntries(v.state.vehicles.map(x => [x.name, x.position]))")
    assert pair["a"] == "bluerov" and pair["b"] == "auv"
    assert pair["distance_m"] == pytest.approx(math.dist(spots["bluerov"], spots["auv"]), rel=0.05)
    acoustic = [p for p in pair["pairs"] if p["src"] == names["bluerov_ac"] and p["dst"] == auv][0]
    assert acoustic["delay_ms"] == pytest.approx(pair["distance_m"] / 1.5, rel=0.01)
    assert acoustic["budget"] and 0 <= acoustic["per"] <= 1
    assert "PER" in browser.js("return document.getElementById('pair').textContent")
    figure(browser.keep(tmp_path, "pair"), "web-pair.png")
    # a reload that swaps a link to a real (emulated EvoLogics) modem: a warning naming the swap
    data = yaml.safe_load(daemon.scene.read_text())
    pty = tmp_path / "modem_rov2"
    emulated = unique("em")
    rov2 = names["rov2_ac"]
    data["links"][emulated] = {"vehicle": "rov2", "address": 9, "bitrate_bps": 2000, "channel": "acoustic",
                               "gli": ["socket"], "emulate": {"protocol": "evologics", "pty": str(pty)}}
    data["links"][rov2] = {"vehicle": "rov2", "backend": "evologics", "port": str(pty), "ack": False, "address": 2, "channel": "acoustic",
                           "gli": ["socket"]}
    daemon.reload(yaml.safe_dump(data, sort_keys=False))
    browser.wait(f"[...document.querySelectorAll('#log-list li[data-kind=\"reload\"][data-level=\"warning\"]')]"
                 f".some(li => li.textContent.includes('{rov2} sim → real evologics'))", "the swap in the log", alive=alive)
    figure(browser.keep(tmp_path, "events"), "web-events.png")


# -- the trace player ---------------------------------------------------------------------------------

PLAYER_SCENE = """\
name: player
seed: 11
duration_s: 60
channels: {ac: {speed_mps: 1500}}
vehicles:
  a: {pose: {static: [0, 0, 5]}}
  b: {pose: {path: {start: [200, 0, 5], legs: [{to: [900, 300, 20], speed_mps: 20}, {to: [200, 0, 5], speed_mps: 20}], loop: true}}}
  c: {pose: {static: [400, -400, 10]}}
links:
  la: {vehicle: a, address: 1, bitrate_bps: 1000, error: {unit: packet, expr: "d / 2000"}, mac: {protocol: cs-aloha, max_range_m: 2000}}
  lb: {vehicle: b, address: 2, bitrate_bps: 1000, error: {unit: packet, expr: "d / 2000"}, range_m: [0, 800], mac: {protocol: cs-aloha, max_range_m: 2000}}
  lc: {vehicle: c, address: 3, bitrate_bps: 2000, fifo_bytes: 60}
flows:
  - {from: la, to: lb, size_bytes: 40, interval_s: 0.7}
  - {from: lb, to: la, size_bytes: 32, interval_s: 0.9, poisson: true}
  - {from: lc, to: "*", size_bytes: 50, interval_s: 0.6, poisson: true}
"""


def test_the_player_steps_from_event_to_event_takes_the_keyboard_and_fits_800_px(tmp_path, browser):  # noqa: F811
    scene = tmp_path / "player.yaml"
    scene.write_text(PLAYER_SCENE)
    trace = tmp_path / "trace.jsonl"
    result = hilgate("sim", str(scene), "--trace", str(trace), "-q")
    assert result.returncode == 0, result.stderr
    viewer = subprocess.Popen([sys.executable, "-m", "hilgate", "view", str(trace), "--scene", str(scene)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = viewer.stdout.readline()
        assert "#token=" in line, line + viewer.stderr.read()
        browser.viewport(1280, 800)
        browser.open(line.split(" at ", 1)[1].split(" ")[0])
        browser.wait("v.authed && v.state && v.scene && !document.getElementById('player').hidden", "the trace")
        # 800 px high and 1280 wide with the player: no scrollbar (a replay was 930 px high)
        assert browser.view("document.documentElement.scrollHeight") <= 800
        assert browser.view("document.documentElement.scrollWidth") <= 1280
        browser.wait("v.player.events.length", "the trace's events")
        events = browser.view("v.player.events")
        assert {e["kind"] for e in events} >= {"burst"} and all(e["level"] in ("info", "warning", "error") for e in events)
        browser.wait(f"document.querySelectorAll('#axis [data-event]').length == {len(events)}", "the events on the axis")
        # the keyboard: n steps to the next event, p back, → a second on, space plays
        body = browser.driver.find_element("tag name", "body")
        body.send_keys("n")
        browser.wait(f"v.state.t == {events[0]['t']}", "the first event")
        browser.wait(f"document.querySelectorAll('#log-list li').length == {sum(e['t'] <= events[0]['t'] for e in events)}",
                     "the log up to the playhead")
        body.send_keys("n")
        second = next(e["t"] for e in events if e["t"] > events[0]["t"])
        browser.wait(f"v.state.t == {second}", "the second event")
        body.send_keys("p")
        browser.wait(f"v.state.t == {events[0]['t']}", "back to the first event")
        from selenium.webdriver.common.keys import Keys
        body.send_keys(Keys.ARROW_RIGHT)
        browser.wait(f"Math.abs(v.state.t - {events[0]['t'] + 1}) < 1e-6", "a second on")
        # at 100×, every frame drawn flies and lands (before, no fate was drawn at all at 100×)
        for _ in range(6):  # 1× → 2, 5, 10, 25, 50, 100×
            body.send_keys("+")
        browser.wait("v.state.speed == 100", "100×")
        browser.driver.find_element("id", "acks").click()  # acknowledgements on request
        start = browser.view("v.state.t")
        body.send_keys(" ")  # (the rest of the trace lasts half a second at 100×: the page keeps what it drew)
        browser.wait("!v.state.playing && v.state.t == v.state.end", "the end")
        played = f"[...v.seen.entries()].filter(([id, e]) => e.tx > {start} && e.states.includes('rx'))"  # sent since
        browser.wait(f"{played}.length >= 10", "fates at 100×")
        browser.wait("[...v.seen.keys()].some(id => id.startsWith('ack:'))", "an acknowledgement drawn")
        states = browser.view(f"{played}.map(([id, e]) => [id, e.tx, e.states])")
        assert all(s[0] == "flight" for _, _, s in states), ([s for s in states if s[2][0] != "flight"], start)
        figure(browser.keep(tmp_path, "player"), "web-player.png")
    finally:
        viewer.send_signal(signal.SIGINT)
        assert viewer.wait(30) == 0
        assert "Traceback" not in viewer.stderr.read()


# -- the trace's events, without a browser -----------------------------------------------------------

def test_a_traces_events_are_bursts_by_cause_reloads_with_their_swaps_hosts_and_poses():
    from hilgate.web.events import BURST_GAP_S, trace_events

    losses = [(t, "a", "col") for t in (1.0, 2.0, 3.0, 4.0)] + [(t, "a", "prop") for t in (1.0, 2.0)] + \
             [(10.0 + BURST_GAP_S + 0.1, "a", "col"), (20.0, "b", "fifo"), (20.1, "b", "fifo"), (20.2, "b", "fifo")]
    sim = {"links": {"a": {"kind": "sim", "backend": "sim"}, "b": {"kind": "sim", "backend": "sim"}}, "name": "s"}
    real = {"links": {"a": {"kind": "real", "backend": "evologics"}, "c": {"kind": "sim", "backend": "sim"}}, "name": "s"}
    events = trace_events([(0.0, sim), (30.0, real)], [(25.0, "B", "down"), (26.0, "B", "up")],
                          {"v": ([5.0, 6.0, 7.0], [[0, 0, 0], None, [1, 1, 1]])}, losses)
    assert [(e["t"], e["kind"], e["level"]) for e in events] == [
        (1.0, "burst", "warning"), (6.0, "pose", "warning"), (7.0, "pose", "info"),
        (20.0, "burst", "warning"), (25.0, "host", "error"), (26.0, "host", "info"), (30.0, "reload", "warning")]
    assert events[0] == {"t": 1.0, "level": "warning", "kind": "burst", "link": "a", "cause": "col", "n": 4, "until": 4.0}
    assert events[-1]["swaps"] == [["a", "sim", "real evologics"]] and events[-1]["added"] == ["c"]
    assert events[-1]["removed"] == ["b"]
    json.dumps(events, allow_nan=False)
