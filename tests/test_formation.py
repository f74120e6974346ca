"""UWSim-NET's third experiment end to end (examples/formation/run.py): a fake BlueROV over MAVLink as
the leader, three simulated followers steered by their applications from what they hear through the
GLI.  The followers lag while the leader moves and settle on their slots once it stops."""

import csv
import json
import os
import subprocess
import sys

import pytest

RUN = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples", "formation", "run.py")


def route_start(trace) -> float:
    """The model time of the operator's first waypoint: the trace's times count from the daemon's start, and
    the applications' start-up before the route (seconds on a loaded host) is no part of what is checked."""
    with open(trace) as handle:
        return next(e["t"] for e in map(json.loads, handle)
                    if e.get("ev") == "enq" and e.get("link", "").endswith("buoy_ac"))


@pytest.mark.parametrize("mac", ["cs-aloha", "s-fama"])
def test_followers_keep_formation_and_settle_once_the_leader_stops(tmp_path, mac):
    result = subprocess.run([sys.executable, RUN, "--seconds", "24", "--legs", "1", "--mac", mac, "--out",
                             str(tmp_path)], capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stdout + result.stderr
    with open(tmp_path / f"formation-{mac}.csv") as handle:
        rows = [(float(t), follower, float(error)) for t, follower, error in list(csv.reader(handle))[1:]]
    followers = {f for _, f, _ in rows}
    assert followers == {"follower1", "follower2", "follower3"}
    start = route_start(tmp_path / f"trace-{mac}.jsonl")
    moving = [e for t, _, e in rows if 1 <= t - start <= 8]  # the leader flies 3 m at 0.3 m/s
    settled = [e for t, _, e in rows if t - start >= 17]      # stopped since ~11 s; the run lasts 24 s from start
    assert settled
    assert max(moving) > 0.05  # the followers do lag behind a moving leader…
    assert max(e for _, _, e in rows) < 1.5  # …but never lose it
    assert max(settled) < 0.2, settled
    assert os.path.exists(tmp_path / f"formation-error-{mac}.png")


def test_the_application_classes_keep_formation_through_hilgate_app(tmp_path):
    """The classes of apps.py (the virtual-time run's) through `hilgate app` against `hilgate run`, with
    the fake BlueROV as the leader: its application passes the waypoints to the autopilot over MAVLink."""
    result = subprocess.run([sys.executable, RUN, "--realtime-apps", "--runs", "1", "--seconds", "24", "--legs", "1",
                             "--mac", "cs-aloha", "--out", str(tmp_path)], capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stdout + result.stderr
    with open(tmp_path / "formation-apps-cs-aloha-1.csv") as handle:
        rows = [(float(t), follower, float(error)) for t, follower, error in list(csv.reader(handle))[1:]]
    assert {f for _, f, _ in rows} == {"follower1", "follower2", "follower3"}
    start = route_start(tmp_path / "trace-apps-cs-aloha-1.jsonl")
    assert max(e for t, _, e in rows if 1 <= t - start <= 10) > 0.05  # the leader did fly: the followers lag
    assert max(e for _, _, e in rows) < 1.5
    settled = [e for t, _, e in rows if t - start >= 17]
    assert settled and max(settled) < 0.2, rows  # and settle once it stops
    assert "leader start delay" in result.stdout
