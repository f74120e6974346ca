"""One application class, two worlds: in-process on the model's clock (``hilgate sim``) and as its own
process against the daemon (``hilgate app``).  The example of docs/applications.md, examples/apps/pingpong.py."""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys

import pytest

from daemon_kit import unique
from hilgate.scene import SceneError, load_scene_text
from hilgate.sim.simulate import Simulation

HERE = os.path.dirname(os.path.abspath(__file__))
EXAMPLE = os.path.join(os.path.dirname(HERE), "examples", "apps", "pingpong.py")


def scene(a: str = "a", b: str = "b", apps: bool = True, count: int = 11) -> str:
    text = f"""\
seed: 3
duration_s: 120
plugins: [{EXAMPLE}]
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  boat: {{pose: {{static: [0, 0, 0]}}}}
  auv: {{pose: {{static: [300, 0, 0]}}}}
links:
  {a}: {{vehicle: boat, address: 1, bitrate_bps: 1000}}
  {b}: {{vehicle: auv, address: 2, bitrate_bps: 1000}}
"""
    if apps:
        text += f"""\
apps:
  - {{class: "pingpong:Ping", links: [{a}], params: {{period_s: 10, peer: 2, count: {count}}}}}
  - {{class: "pingpong:Pong", links: [{b}]}}
"""
    return text


def airtime(text: bytes) -> float:
    return (1 + 2 + len(text) + 2) * 8 / 1000  # vl2b at 1000 b/s


def test_applications_run_in_virtual_time_exactly_and_identically_for_a_seed():
    traces = []
    for _ in range(2):
        out = io.StringIO()
        simulation = Simulation(load_scene_text(scene()), trace=out)
        simulation.run()
        traces.append(out.getvalue())
    assert traces[0] == traces[1]
    ping = simulation.apps.contexts[0].app
    # every ping at 10·k s is answered at once; 300 m each way
    expected = [airtime(b"ping %d" % k) + 0.2 + airtime(b"pong %d" % k) + 0.2 for k in range(1, 12)]
    assert ping.round_trips == pytest.approx(expected, abs=1e-9) and not ping.sent
    assert len(ping.round_trips) == 11


def test_an_application_that_is_not_one_or_on_no_simulated_link_is_a_scene_error():
    bad = scene().replace("pingpong:Pong", "pingpong:Application2")
    with pytest.raises(SceneError, match=r"apps\[1\]\.class: .*not an application"):
        load_scene_text(bad)
    with pytest.raises(SceneError, match=r"apps\[1\]\.links\[0\]: no link 'nowhere'"):
        load_scene_text(scene().replace("links: [b]", "links: [nowhere]"))


def test_the_same_classes_run_as_processes_against_the_daemon(daemon_of):
    a, b = unique("pa"), unique("pb")
    daemon = daemon_of(scene(a, b, apps=False), [a, b])
    processes = []
    try:
        common = ["--runtime-dir", daemon.runtime]
        pong = subprocess.Popen([sys.executable, "-m", "hilgate", "-v", "app", f"{EXAMPLE}:Pong", "--link", b,
                                 "--until", "60", *common], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)
        processes.append(pong)
        daemon.wait_clients(b)  # Pong hears only the pings sent once it is attached: on a loaded host its start-up
        # can take longer than Ping's own start-up and first period together
        ping = subprocess.run([sys.executable, "-m", "hilgate", "-v", "app", f"{EXAMPLE}:Ping", "--link", a,
                               "--param", "period_s=1", "--param", "peer=2", "--param", "count=3", "--seed", "1",
                               "--until", "8", *common], capture_output=True, text=True, timeout=60)
        assert ping.returncode == 0, ping.stdout + ping.stderr
        trips = [float(x) for x in re.findall(r"pong \d+ after ([0-9.]+) s", ping.stderr)]
        assert len(trips) == 3, ping.stderr
        model = airtime(b"ping 1") + 0.2 + airtime(b"pong 1") + 0.2
        assert all(trip >= model - 0.002 for trip in trips)  # never sooner than the model (no upper bound)
        assert "3 round trips, 0 pings unanswered" in ping.stderr
        daemon.stop()
        events = daemon.trace_events()
        enq = sorted(e["t"] for e in events if e.get("ev") == "enq" and e["link"] == a)
        back = sorted(e["t"] for e in events if e.get("ev") == "rx" and e["link"] == a)
        answered = sorted(e["t"] for e in events if e.get("ev") == "enq" and e["link"] == b)
        heard = sorted(e["t"] for e in events if e.get("ev") == "rx" and e["link"] == b)
        assert len(enq) == len(back) == len(heard) == len(answered) == 3
        for sent, at_b in zip(enq, heard):  # the model's share of each trip, exact in the trace
            assert at_b - sent == pytest.approx(airtime(b"ping 1") + 0.2, abs=1e-6)
        for reply, returned in zip(answered, back):
            assert returned - reply == pytest.approx(airtime(b"pong 1") + 0.2, abs=1e-6)
    finally:
        for process in processes:
            process.terminate()
            process.wait(10)


def test_hilgate_app_refuses_what_is_not_an_application_in_one_line(tmp_path):
    result = subprocess.run([sys.executable, "-m", "hilgate", "app", f"{EXAMPLE}:Nothing", "--link", "x"],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2 and "not an application" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("mac,mean,largest", [("cs-aloha", "0.140", ["0.360", "0.360", "0.361"]),
                                               ("s-fama", "0.194", ["0.688", "0.688", "0.689"])])
def test_the_formation_in_virtual_time_gives_the_readmes_figures(tmp_path, mac, mean, largest):
    """UWSim-NET's third experiment with the applications of examples/formation/apps.py, in virtual time
    (scenes/paper-exp3-formation-virtual.yaml): the follower errors docs/paper.md prints, to the digit
    (deterministic: no host load in them)."""
    formation = os.path.join(os.path.dirname(HERE), "examples", "formation")
    result = subprocess.run([sys.executable, os.path.join(formation, "run.py"), "--virtual", "--mac", mac,
                             "--seconds", "60", "--out", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    lines = [line for line in result.stdout.splitlines() if line.strip().startswith("follower")]
    assert len(lines) == 3
    for line, top in zip(lines, largest):
        assert f"mean {mean} m, max {top} m / mean 0.000 m, final 0.000 m" in line, lines


def test_the_operator_repeats_one_waypoint_at_a_time(tmp_path):
    """The operator sends each leg's waypoint every repeat_s (2–2.2 s) and stops repeating it when the
    next leg begins: six per 12 s leg.  (Its repetitions once outlived their leg, so the buoy sent 6, 12
    and 18 waypoints in legs 1–3, and under S-FAMA their RTSs collided with the leader's broadcasts.)"""
    import json

    out = io.StringIO()
    scene = os.path.join(os.path.dirname(HERE), "scenes", "paper-exp3-formation-virtual.yaml")
    from hilgate.scene import load_scene

    Simulation(load_scene(scene, ["links.*.mac.protocol=s-fama", "links.*.mac.backoff_s=null"]), trace=out,
               until=60).run()
    sent = [json.loads(line) for line in out.getvalue().splitlines()]
    waypoints = [(e["t"], e) for e in sent if e.get("ev") == "enq" and e["link"] == "buoy_ac"]
    assert [sum(1 for t, _ in waypoints if 12 * k <= t < 12 * (k + 1)) for k in range(4)] == [6, 6, 6, 0]
