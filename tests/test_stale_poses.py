"""Issue 41: a silent pose source is flagged stale everywhere an operator looks: the page (its vehicles'
table, the chart, the event log), ``hilgate status`` (text and JSON) and the daemon's log, once when it
goes stale and once when it is fresh again.  docs/live-vehicles.md promised it; before, nothing showed it.
``hilgate status --json`` also carries ``web.url``, as docs/live-view.md says."""

from __future__ import annotations

import json
import socket

import pytest

from browser_kit import browser  # noqa: F401  (the fixture)
from daemon_kit import free_port, hilgate, unique, wait_until
from test_live_poses import FakeBlueRov

pytest.importorskip("tornado", reason="the web view needs tornado: pip install -e '.[test]'")


def scene(port: int, topside: str, bluerov: str) -> str:
    return f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  topside: {{pose: {{static: [0, 0, 0]}}}}
  bluerov:
    pose: {{mavlink: {{url: "udpin:127.0.0.1:{port}", system_id: 1}}}}
    stale_after_s: 1.0
    initial: [20, 0, 5]
links:
  {topside}: {{vehicle: topside, address: 1, bitrate_bps: 1000, gli: [socket]}}
  {bluerov}: {{vehicle: bluerov, address: 2, bitrate_bps: 1000, gli: [socket]}}
"""


def status_json(daemon) -> dict:
    result = hilgate("status", "--json", "--runtime-dir", daemon.runtime)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def bluerov(status: dict) -> dict:
    return next(v for v in status["vehicles"] if v["name"] == "bluerov")


def test_a_silent_pose_source_is_stale_on_the_page_in_status_and_in_the_log(tmp_path, browser, daemon_of):  # noqa: F811
    port = free_port(socket.SOCK_DGRAM)
    topside, rov = unique("st"), unique("sr")
    daemon = daemon_of(scene(port, topside, rov), [topside, rov], "--web", "0")
    alive = lambda: daemon.process.poll() is None or pytest.fail(daemon.output())  # noqa: E731
    # nothing ever came from the vehicle's MAVLink endpoint: stale ("never heard") once a second has passed
    wait_until(lambda: bluerov(status_json(daemon)).get("stale") == "never", "the silent source flagged")
    status = status_json(daemon)
    assert status["web"]["url"].startswith("http://127.0.0.1:") and status["web"]["pages"] == 0
    text = hilgate("status", "--runtime-dir", daemon.runtime).stdout
    assert [line for line in text.splitlines() if line.startswith("bluerov")][0].endswith("STALE (never heard)")
    wait_until(lambda: "vehicle bluerov: no pose from mavlink after" in daemon.output(), "the log's warning")
    url = hilgate("view", "--runtime-dir", daemon.runtime).stdout.strip()
    browser.viewport(1280, 800)
    browser.open(url)
    browser.wait("v.authed && v.state", "the page")
    browser.wait("document.querySelector('tr[data-vehicle=\"bluerov\"]')?.dataset.stale == 'never'", "the row flagged")
    assert browser.js("return document.querySelector('tr[data-vehicle=\"bluerov\"] td.pose').textContent") == "NO POSE"
    browser.wait("[...document.querySelectorAll('#log-list li[data-kind=\"pose\"][data-level=\"warning\"]')]"
                 ".some(li => li.textContent.includes('bluerov'))", "the event log's warning", alive=alive)
    # the vehicle speaks: fresh everywhere, and the log says so
    vehicle = FakeBlueRov(port)
    try:
        wait_until(lambda: bluerov(status_json(daemon)).get("stale") is None and bluerov(status_json(daemon))["age_s"]
                   is not None, "the pose fresh")
        browser.wait("document.querySelector('tr[data-vehicle=\"bluerov\"]')?.dataset.stale == ''", "the row fresh")
        browser.wait("!!document.querySelector('#top [data-vehicle=\"bluerov\"]:not([data-stale])')", "the vehicle fresh")
        wait_until(lambda: "vehicle bluerov: pose fresh again from mavlink" in daemon.output(), "the log's line")
        # the tether cut: stale on the chart (a halo, STALE by its name), in the table, the log and status
        vehicle.sending = False
        browser.wait("!!document.querySelector('#top [data-vehicle=\"bluerov\"][data-stale=\"stale\"]')",
                     "the vehicle flagged on the chart", alive=alive)
        browser.wait("document.querySelector('tr[data-vehicle=\"bluerov\"] td.pose').textContent == 'STALE'", "the row STALE")
        assert "bluerov · STALE" in browser.js("return document.querySelector('#top [data-label=\"bluerov\"]').textContent")
        browser.wait("[...document.querySelectorAll('#log-list li[data-kind=\"pose\"]')].some(li => /pose stale/.test(li.textContent))",
                     "the event log's line", alive=alive)
        wait_until(lambda: "vehicle bluerov: pose stale: nothing from mavlink for" in daemon.output(), "the log's warning")
        assert bluerov(status_json(daemon))["stale"] == "stale"
        assert daemon.output().count("vehicle bluerov: pose stale") == 1  # once, not every half second
        browser.keep(tmp_path, "stale")
    finally:
        vehicle.close()
