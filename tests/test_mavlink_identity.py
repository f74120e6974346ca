"""hilgate on a vehicle's MAVLink network: it sends nothing the scene did not ask for, and never as a
ground station.

ArduSub takes a HEARTBEAT from system 255 (SYSID_MYGCS) as its ground station being alive.  Each
vehicle here is pymavlink itself over UDP loopback, sending as ArduSub does (system N, component 1,
MAV_TYPE_SUBMARINE) and recording every message hilgate sends it.  Ports are picked by the kernel.
"""

import socket
import threading
import time

import pytest

import hilgate.drivers.mavlink_source  # noqa: F401  (sets MAVLink 2 before pymavlink is imported)
from daemon_kit import free_port, in_background, unique, wait_until
from hilgate.scene import SceneError, load_scene_text
from pymavlink import mavutil

MAV = mavutil.mavlink


class Vehicle:
    """ArduSub as seen over MAVLink: HEARTBEAT, LOCAL_POSITION_NED and ATTITUDE at 20 Hz as
    ``system_id``/1, and a record of everything it receives.  On ``udpin:127.0.0.1:0`` it is like a
    router that streams only to endpoints it has heard from (pymavlink answers the last sender)."""

    def __init__(self, url: str, system_id: int = 1):
        self.link = mavutil.mavlink_connection(url, source_system=system_id, source_component=1)
        self.port = self.link.port.getsockname()[1]
        self.received: list = []
        self.lock = threading.Lock()
        self.stop, self.thread = in_background(self._run)

    def _run(self, stop):
        boot = time.monotonic()
        while not stop.is_set():
            ms = int((time.monotonic() - boot) * 1000)
            mav = self.link.mav
            try:
                mav.heartbeat_send(MAV.MAV_TYPE_SUBMARINE, MAV.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, MAV.MAV_STATE_ACTIVE)
                mav.local_position_ned_send(ms, 4.0, 3.0, 2.0, 0.0, 0.0, 0.0)
                mav.attitude_send(ms, 0.0, 0.0, 0.5, 0, 0, 0)
            except OSError:
                pass
            deadline = time.monotonic() + 0.05
            while time.monotonic() < deadline:
                message = self.link.recv_match(blocking=True, timeout=0.01)
                if message is not None and message.get_type() != "BAD_DATA":
                    with self.lock:
                        self.received.append(message)

    def messages(self, kind: str | None = None) -> list:
        with self.lock:
            return [m for m in self.received if kind is None or m.get_type() == kind]

    def close(self):
        self.stop.set()
        self.thread.join()
        self.link.close()


def position(daemon, vehicle):
    return next(v for v in daemon.status()["vehicles"] if v["name"] == vehicle)["position"]


def assert_never_a_ground_station(messages):
    for m in messages:
        assert m.get_srcSystem() != 255 and m.get_srcComponent() not in (1, 190), m
        if m.get_type() == "HEARTBEAT":
            assert m.type != MAV.MAV_TYPE_GCS and m.type == MAV.MAV_TYPE_ONBOARD_CONTROLLER, m
            assert m.autopilot == MAV.MAV_AUTOPILOT_INVALID, m


SCENE = """\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
{vehicles}
links:
  {link}: {{vehicle: {first}, address: 1}}
"""


def test_by_default_a_vehicle_gets_nothing_and_asked_rates_come_from_a_companion(daemon_of):
    quiet_port, rates_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    link = unique("mq")
    vehicles = f"""\
  quiet: {{pose: {{mavlink: {{url: "udpin:127.0.0.1:{quiet_port}"}}}}}}
  rates:
    pose: {{mavlink: {{url: "udpin:127.0.0.1:{rates_port}", system_id: 2, message_rates: {{ATTITUDE: 5}}}}}}
"""
    daemon = daemon_of(SCENE.format(vehicles=vehicles, link=link, first="quiet"), [link])
    quiet = Vehicle(f"udpout:127.0.0.1:{quiet_port}", system_id=1)
    rates = Vehicle(f"udpout:127.0.0.1:{rates_port}", system_id=2)
    try:
        wait_until(lambda: position(daemon, "quiet") == [4.0, 3.0, 2.0] and position(daemon, "rates") is not None)
        wait_until(lambda: rates.messages("COMMAND_LONG"), "the scene asked for message rates")
        time.sleep(3.0)  # three heartbeat periods: a heartbeat hilgate sent would have arrived by now
        assert quiet.messages() == []  # nothing the scene did not ask for: no heartbeat, no request
        assert rates.messages("HEARTBEAT") == []
        (command,) = rates.messages("COMMAND_LONG")  # asked once, on the autopilot's first heartbeat
        assert command.command == MAV.MAV_CMD_SET_MESSAGE_INTERVAL and command.param1 == MAV.MAVLINK_MSG_ID_ATTITUDE
        assert command.param2 == 200000 and (command.target_system, command.target_component) == (2, 1)
        # as the vehicle's companion computer: its system id, hilgate's own component
        assert (command.get_srcSystem(), command.get_srcComponent()) == (2, 192)
        assert_never_a_ground_station(quiet.messages() + rates.messages())
    finally:
        quiet.close()
        rates.close()


def test_an_asked_heartbeat_is_an_onboard_peripherals_and_feedback_goes_as_the_same(daemon_of):
    link = unique("mh")
    # both vehicles are routers that stream only to endpoints they have heard from: hilgate speaks first
    configured = Vehicle("udpin:127.0.0.1:0", system_id=1)
    companion = Vehicle("udpin:127.0.0.1:0", system_id=3)
    autopilot = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=1)
    feedback_port = autopilot.port.getsockname()[1]
    vehicles = f"""\
  configured:
    pose:
      mavlink:
        url: "udpout:127.0.0.1:{configured.port}"
        heartbeat: {{system_id: 7, component_id: 193, rate_hz: 5}}
        message_rates: {{LOCAL_POSITION_NED: 10}}
    feedback: {{url: "udpout:127.0.0.1:{feedback_port}", message: vision_position_estimate, rate_hz: 10}}
  companion: {{pose: {{mavlink: {{url: "udpout:127.0.0.1:{companion.port}", system_id: 3, heartbeat: true}}}}}}
"""
    daemon = daemon_of(SCENE.format(vehicles=vehicles, link=link, first="configured"), [link])
    try:
        wait_until(lambda: position(daemon, "configured") == [4.0, 3.0, 2.0], "no pose: hilgate never spoke")
        wait_until(lambda: position(daemon, "companion") == [4.0, 3.0, 2.0], "no pose: hilgate never spoke")
        wait_until(lambda: len(configured.messages("HEARTBEAT")) >= 3 and len(companion.messages("HEARTBEAT")) >= 2)
        wait_until(lambda: configured.messages("COMMAND_LONG"))
        for beat in configured.messages("HEARTBEAT"):
            assert (beat.get_srcSystem(), beat.get_srcComponent()) == (7, 193)
        for beat in companion.messages("HEARTBEAT"):  # true: the vehicle's system id, component 192
            assert (beat.get_srcSystem(), beat.get_srcComponent()) == (3, 192)
        (command,) = configured.messages("COMMAND_LONG")
        assert (command.get_srcSystem(), command.get_srcComponent()) == (7, 193)
        assert command.param1 == MAV.MAVLINK_MSG_ID_LOCAL_POSITION_NED and command.param2 == 100000
        estimate = autopilot.recv_match(type="VISION_POSITION_ESTIMATE", blocking=True, timeout=30)
        assert estimate is not None and (estimate.x, estimate.y, estimate.z) == pytest.approx((4.0, 3.0, 2.0))
        assert (estimate.get_srcSystem(), estimate.get_srcComponent()) == (7, 193)  # one identity for all
        assert_never_a_ground_station(configured.messages() + companion.messages() + [estimate])
    finally:
        configured.close()
        companion.close()
        autopilot.close()


def mavlink_scene(options: str) -> str:
    return f"channels: {{ac: {{speed_mps: 1}}}}\nvehicles:\n  r: {{pose: {{mavlink: {options}}}}}\nlinks: {{}}\n"


def heartbeat_of(options: str):
    params = dict(load_scene_text(mavlink_scene(options)).vehicles["r"].pose.params)["mavlink"]
    return dict(params)["heartbeat"]


def test_heartbeat_key_defaults():
    assert heartbeat_of("{url: 'udpin:0.0.0.0:14551'}") is None
    assert heartbeat_of("{url: 'udpin:0.0.0.0:14551', system_id: 1, heartbeat: false}") is None
    assert dict(heartbeat_of("{url: u, system_id: 1, heartbeat: true}")) == \
        {"system_id": 1, "component_id": 192, "rate_hz": 1.0}
    assert dict(heartbeat_of("{url: u, system_id: 1, heartbeat: {system_id: 42, component_id: 191}}")) == \
        {"system_id": 42, "component_id": 191, "rate_hz": 1.0}


@pytest.mark.parametrize("options,why", [
    ("{url: u, heartbeat: true}", "needs a system id"),
    ("{url: u, system_id: 255, heartbeat: true}", "mavlink.system_id: 255 is the ground station's"),
    ("{url: u, heartbeat: {system_id: 255}}", "heartbeat.system_id: 255 is the ground station's"),
    ("{url: u, system_id: 1, heartbeat: {component_id: 1}}", "component 1 is the autopilot's"),
    ("{url: u, system_id: 1, heartbeat: {component_id: 190}}", "ground station's"),
    ("{url: u, system_id: 1, heartbeat: {type: 6}}", "unknown key"),
    ("{url: u, system_id: 1, heartbeat: {rate_hz: 0}}", "rate_hz"),
    ("{url: u, system_id: 1, heartbeat: 1}", "must be true, false or"),
])
def test_a_heartbeat_that_would_pose_as_a_ground_station_or_the_autopilot_is_refused(options, why):
    with pytest.raises(SceneError, match=why):
        load_scene_text(mavlink_scene(options))
