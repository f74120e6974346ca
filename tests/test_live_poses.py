"""Live vehicles: the pose board's rules, application-steered vehicles, and a fake BlueROV over MAVLink.

The fake BlueROV is pymavlink itself, sending HEARTBEAT, LOCAL_POSITION_NED, ATTITUDE and
GLOBAL_POSITION_INT to the daemon over UDP loopback, as BlueOS sends them to the topside.
"""

import socket
import subprocess
import sys
import time

import pytest

import hilgate.drivers.mavlink_source  # noqa: F401  (sets MAVLink 2 before pymavlink is imported)
from daemon_kit import assert_the_walk_traced, free_port, in_background, unique, walk_a_live_vehicle
from hilgate.client import Link
from hilgate.models.controlled import Controlled
from hilgate.models.medium import Channel
from hilgate.sim.live_vehicle import LiveVehicle
from netkit import Net
from pymavlink import mavutil


# -- the pose board -----------------------------------------------------------------------------------


def test_merge_takes_each_axis_from_its_source():
    v = LiveVehicle("rov", merge={"x": "aruco", "y": "aruco", "z": "mavlink"})
    v.update("mavlink", 1.0, {"x": 9.0, "y": 9.0, "z": 2.5})
    assert v.position(1.0) is None  # x and y not known yet
    v.update("aruco", 1.1, {"x": 1.0, "y": 2.0, "z": 7.0})
    assert v.position(1.1) == (1.0, 2.0, 2.5)
    assert v.sources() == "aruco+mavlink"


def test_stale_pose_hold_or_drop():
    hold = LiveVehicle("a", stale_after_s=1.0, stale="hold")
    drop = LiveVehicle("b", stale_after_s=1.0, stale="drop")
    for v in (hold, drop):
        v.update("mavlink", 0.0, {"x": 1.0, "y": 2.0, "z": 3.0})
    assert hold.position(0.9) == drop.position(0.9) == (1.0, 2.0, 3.0)
    assert hold.position(5.0) == (1.0, 2.0, 3.0) and hold.stale(5.0)
    assert drop.position(5.0) is None
    assert hold.age(5.0) == 5.0


def test_extrapolation_over_short_gaps_only():
    v = LiveVehicle("a", stale_after_s=10.0, extrapolate_s=0.5)
    v.update("mavlink", 0.0, {"x": 0.0, "y": 0.0, "z": 0.0}, {"x": 1.0, "y": 0.0, "z": -0.5})
    assert v.position(0.4) == pytest.approx((0.4, 0.0, -0.2))
    assert v.position(2.0) == (0.0, 0.0, 0.0)  # beyond extrapolate_s: the last measurement


def test_initial_position_until_the_first_measurement():
    v = LiveVehicle("a", initial=(5.0, 0.0, 1.0), stale="drop")
    assert v.position(0.0) == (5.0, 0.0, 1.0) and v.age(0.0) is None


# -- application-steered vehicles -----------------------------------------------------------------------


def test_controlled_vehicle_moves_at_most_at_its_speed_and_the_delay_follows():
    rov = Controlled((150.0, 0.0, 0.0), max_speed_mps=15.0)
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (0, 0, 0), bitrate_bps=1000)
    net.modem("b", rov, bitrate_bps=1000)
    rov.go_to(0.0, (450.0, 0.0, 0.0))  # 300 m at 15 m/s: there at t = 20 s
    for t in (0.0, 10.0, 20.0, 30.0):
        net.send("a", "b", 10, at=t)
    net.run()
    delays = [round(t - f.t0, 9) for t, f in net.delivered["b"]]
    assert delays == [0.18, 0.28, 0.38, 0.38]
    rov.set_velocity(30.0, (0.0, 300.0, 0.0))  # clamped to 15 m/s
    assert rov.position(32.0) == pytest.approx((450.0, 30.0, 0.0))


# -- the daemon with a fake BlueROV -----------------------------------------------------------------------


class FakeBlueRov:
    """ArduSub as seen from the topside: pymavlink sending to the daemon's udpin port at 20 Hz."""

    def __init__(self, port: int):
        self.link = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
        self.position = [150.0, 0.0, 5.0]
        self.sending = True
        self.stop, self.thread = in_background(self._run)

    def _run(self, stop):
        boot = time.monotonic()
        while not stop.is_set():
            if self.sending:
                ms = int((time.monotonic() - boot) * 1000)
                mav = self.link.mav
                mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_SUBMARINE, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                   0, 0, 0)
                x, y, z = self.position
                mav.local_position_ned_send(ms, x, y, z, 0.0, 0.0, 0.0)
                mav.attitude_send(ms, 0.1, -0.2, 1.5, 0, 0, 0)
                mav.global_position_int_send(ms, int(39.99 * 1e7), int(-0.07 * 1e7), 0, int(-z * 1000), 0, 0, 0, 0)
            stop.wait(0.05)

    def close(self):
        self.stop.set()
        self.thread.join()


def live_scene(port: int, bluerov: str, topside: str, extra: str = "") -> str:
    return f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  topside: {{pose: {{static: [0, 0, 0]}}}}
  bluerov:
    pose: {{mavlink: {{url: "udpin:127.0.0.1:{port}", system_id: 1}}}}
    stale_after_s: 1.0
    stale: drop
{extra}links:  # strict: frames go to the addressed modem only, so one out of range is traced as such
  {topside}: {{vehicle: topside, address: 1, bitrate_bps: 1000, addressing: strict}}
  {bluerov}: {{vehicle: bluerov, address: 2, bitrate_bps: 1000, addressing: strict}}
"""


def test_fake_bluerov_over_mavlink_moves_the_modem_and_goes_stale(daemon_of, busy_host):
    port = free_port(socket.SOCK_DGRAM)
    topside, bluerov = unique("top"), unique("rov")
    daemon = daemon_of(live_scene(port, bluerov, topside), [topside, bluerov])
    vehicle = FakeBlueRov(port)
    try:
        def cut_the_tether():  # silence, stale, dropped
            vehicle.sending = False

        seen = walk_a_live_vehicle(daemon, topside, bluerov, lambda: setattr(vehicle, "position", [300.0, 0.0, 5.0]),
                                   cut_the_tether)
        assert seen["source"] == "mavlink" and seen["age_s"] is not None  # fresh: a stale one is dropped
        assert_the_walk_traced(daemon)
    finally:
        vehicle.close()


def test_applications_steer_controlled_vehicles_and_feedback_reaches_the_autopilot(daemon_of):
    autopilot_port = free_port(socket.SOCK_DGRAM)
    autopilot = mavutil.mavlink_connection(f"udpin:127.0.0.1:{autopilot_port}", source_system=1)
    follower = unique("fol")
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  follower:
    pose: {{controlled: {{start: [0, 0, 2], max_speed_mps: 0.5}}}}
    feedback: {{url: "udpout:127.0.0.1:{autopilot_port}", message: vision_position_estimate, rate_hz: 10}}
links:
  {follower}: {{vehicle: follower, address: 1}}
"""
    daemon = daemon_of(scene, [follower])
    try:
        with Link.open(follower, runtime_dir=daemon.runtime) as link:
            start = time.monotonic()
            assert link.command({"class": "GOTO", "position": [3, 4, 2]})["ok"]
            time.sleep(1.0)
            moved = link.command({"class": "POSE"})["position"]
            elapsed = time.monotonic() - start  # encloses the daemon's time between the two commands
            travelled = (moved[0] ** 2 + moved[1] ** 2) ** 0.5
            assert 0.4 <= travelled <= 0.5 * elapsed + 1e-6  # at most 0.5 m/s, however loaded the host
            assert link.command({"class": "VELOCITY", "velocity": [0, 0]})["class"] == "ERROR"
        message = autopilot.recv_match(type="VISION_POSITION_ESTIMATE", blocking=True, timeout=30)
        assert message is not None and message.z == pytest.approx(2.0) and message.x > 0
        # as the vehicle's companion computer (its system id, component 192), never as a ground station (255)
        assert (message.get_srcSystem(), message.get_srcComponent()) == (1, 192)
        follow = subprocess.Popen([sys.executable, "-m", "hilgate", "pose", "follower", "--runtime-dir",
                                   daemon.runtime, "--interval", "0.2"], stdout=subprocess.PIPE, text=True)
        lines = [follow.stdout.readline() for _ in range(2)]
        follow.kill()
        follow.wait()
        assert all("follower" in line and "controlled" in line for line in lines)
    finally:
        autopilot.close()


def test_live_pose_scene_errors(tmp_path):
    from hilgate.scene import SceneError, load_scene_text

    with pytest.raises(SceneError, match="need 'merge'"):
        load_scene_text("channels: {ac: {speed_mps: 1}}\nvehicles:\n  r:\n    pose:\n"
                        "      mavlink: {url: 'udpin:0.0.0.0:14551'}\n      aruco: {camera: c, marker: 1}\nlinks: {}\n")
    with pytest.raises(SceneError, match="only for vehicles with a live pose"):
        load_scene_text("channels: {ac: {speed_mps: 1}}\nvehicles:\n  r: {pose: {static: [0,0,0]}, stale: drop}\n"
                        "links: {}\n")
    with pytest.raises(SceneError, match="no camera 'c'"):
        load_scene_text("channels: {ac: {speed_mps: 1}}\nvehicles:\n  r: {pose: {aruco: {camera: c, marker: 1}}}\n"
                        "links: {}\n")
