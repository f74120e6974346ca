"""A BlueROV2's pose from ArduSub over MAVLink 2 (pymavlink), and the camera's pose fed back to it.

:class:`MavlinkSource` reads in its own thread (pymavlink blocks) and hands every measurement to the
daemon's loop.  What it uses, in ArduSub's terms (``shared/protocols/s100-mavlink-aruco.md``):
``LOCAL_POSITION_NED`` (x, y, z and velocities, relative to the EKF origin) and ``ATTITUDE`` when the
vehicle sends them; else ``GLOBAL_POSITION_INT`` around a configured origin; else, with no origin,
the depth alone (``relative_alt``, negative under water).  In a bare tank ArduSub sends no
LOCAL_POSITION_NED at all, which is why a camera (merge) often gives x and y.  On the vehicle's
first heartbeat it may ask for message rates (``MAV_CMD_SET_MESSAGE_INTERVAL``).  A silent or
vanished endpoint is not an error: the pose goes stale and the connection is retried.

:class:`Feedback` sends the vehicle's position back as ``VISION_POSITION_ESTIMATE`` (ArduPilot's
ExternalNav) or ``GPS_INPUT`` around an origin (what the UWSim-NET authors did), so a real BlueROV can
hold station in a tank without GPS.
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from typing import Any, Callable

os.environ.setdefault("MAVLINK20", "1")  # before pymavlink is imported: MAVLink 2 framing
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")
from pymavlink import mavutil  # noqa: E402

log = logging.getLogger(__name__)

EARTH_RADIUS = 6378137.0
POSE_MESSAGES = ["HEARTBEAT", "LOCAL_POSITION_NED", "ATTITUDE", "GLOBAL_POSITION_INT"]
LOCAL_FRESH_S = 2.0


def ned_from_global(lat_deg: float, lon_deg: float, origin: tuple[float, float, float]) -> tuple[float, float]:
    """North and east metres of a latitude/longitude from ``origin`` (flat earth: tank-sized areas)."""
    lat0, lon0, _ = origin
    north = math.radians(lat_deg - lat0) * EARTH_RADIUS
    east = math.radians(lon_deg - lon0) * EARTH_RADIUS * math.cos(math.radians(lat0))
    return north, east


def global_from_ned(north: float, east: float, origin: tuple[float, float, float]) -> tuple[float, float]:
    lat0, lon0, _ = origin
    lat = lat0 + math.degrees(north / EARTH_RADIUS)
    lon = lon0 + math.degrees(east / (EARTH_RADIUS * math.cos(math.radians(lat0))))
    return lat, lon


class MavlinkSource:
    """Feeds ``deliver(position, velocity, attitude)`` (called from this source's thread; make it
    thread-safe) with what the vehicle reports."""

    def __init__(self, name: str, url: str, deliver: Callable[..., Any], system_id: int | None = None,
                 origin: tuple[float, float, float] | None = None, message_rates: tuple = (),
                 heartbeat: bool = True):
        self.name = name
        self.url = url
        self.deliver = deliver
        self.system_id = system_id
        self.origin = origin
        self.message_rates = dict(message_rates)
        self.heartbeat = heartbeat
        self.messages = 0
        self.connected = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"mavlink-{name}", daemon=True)
        self._last_local = -math.inf
        self._asked = False

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                connection = mavutil.mavlink_connection(self.url, source_system=255, source_component=190)
            except Exception as exc:  # any pymavlink/OS error: the endpoint is not there yet
                log.warning("mavlink %s: cannot open %s (%s); retrying", self.name, self.url, exc)
                self._stop.wait(2.0)
                continue
            self.connected = True
            try:
                self._serve(connection)
            except Exception as exc:
                log.warning("mavlink %s: %s; reconnecting", self.name, exc)
                self._stop.wait(1.0)
            finally:
                self.connected = False
                try:
                    connection.close()
                except Exception:
                    pass

    def _serve(self, connection: Any) -> None:
        last_beat = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if self.heartbeat and now - last_beat >= 1.0:
                last_beat = now
                try:
                    connection.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID,
                                                  0, 0, 0)
                except OSError:
                    pass  # udpin before the vehicle has spoken: nobody to send to yet
            message = connection.recv_match(type=POSE_MESSAGES, blocking=True, timeout=0.2)
            if message is None:
                continue
            if self.system_id is not None and message.get_srcSystem() != self.system_id:
                continue
            self.messages += 1
            self._handle(connection, message)

    def _handle(self, connection: Any, message: Any) -> None:
        kind = message.get_type()
        if kind == "HEARTBEAT":
            if self.message_rates and not self._asked:
                self._asked = True
                for name, rate in self.message_rates.items():
                    message_id = getattr(mavutil.mavlink, f"MAVLINK_MSG_ID_{name.upper()}", None)
                    if message_id is None:
                        log.warning("mavlink %s: unknown message %s in message_rates", self.name, name)
                        continue
                    connection.mav.command_long_send(
                        message.get_srcSystem(), message.get_srcComponent(),
                        mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, message_id, 1e6 / rate, 0, 0, 0, 0, 0)
        elif kind == "LOCAL_POSITION_NED":
            self._last_local = time.monotonic()
            self.deliver({"x": message.x, "y": message.y, "z": message.z},
                         {"x": message.vx, "y": message.vy, "z": message.vz}, None)
        elif kind == "ATTITUDE":
            self.deliver({}, None, (message.roll, message.pitch, message.yaw))
        elif kind == "GLOBAL_POSITION_INT":
            if time.monotonic() - self._last_local < LOCAL_FRESH_S:
                return  # the local position is better
            depth = -message.relative_alt / 1000.0
            velocity = {"x": message.vx / 100.0, "y": message.vy / 100.0, "z": message.vz / 100.0}
            if self.origin is not None:
                north, east = ned_from_global(message.lat / 1e7, message.lon / 1e7, self.origin)
                self.deliver({"x": north, "y": east, "z": depth}, velocity, None)
            else:
                self.deliver({"z": depth}, {"z": velocity["z"]}, None)


class Feedback:
    """Sends a vehicle's board position to its autopilot at ``rate_hz`` (from the daemon's loop)."""

    def __init__(self, name: str, url: str, message: str, rate_hz: float, origin, system_id: int,
                 position: Callable[[], tuple | None], attitude: Callable[[], tuple | None], scheduler: Any):
        self.name = name
        self.message = message
        self.period = 1.0 / rate_hz
        self.origin = origin
        self.target = system_id
        self.position = position
        self.attitude = attitude
        self.scheduler = scheduler
        self.sent = 0
        self.connection = mavutil.mavlink_connection(url, source_system=255, source_component=197)
        self.timer = scheduler.at(scheduler.now() + self.period * getattr(scheduler, "speed", 1.0), self._tick)

    def _tick(self) -> None:
        scheduler = self.scheduler
        self.timer = scheduler.at(scheduler.now() + self.period * getattr(scheduler, "speed", 1.0), self._tick)
        position = self.position()
        if position is None:
            return
        usec = int(time.time() * 1e6)
        try:
            if self.message == "vision_position_estimate":
                roll, pitch, yaw = self.attitude() or (0.0, 0.0, 0.0)
                self.connection.mav.vision_position_estimate_send(usec, *position, roll, pitch, yaw)
            else:
                lat, lon = global_from_ned(position[0], position[1], self.origin)
                ignore = (mavutil.mavlink.GPS_INPUT_IGNORE_FLAG_ALT | mavutil.mavlink.GPS_INPUT_IGNORE_FLAG_VEL_HORIZ
                          | mavutil.mavlink.GPS_INPUT_IGNORE_FLAG_VEL_VERT
                          | mavutil.mavlink.GPS_INPUT_IGNORE_FLAG_SPEED_ACCURACY
                          | mavutil.mavlink.GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY
                          | mavutil.mavlink.GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY)
                self.connection.mav.gps_input_send(usec, 0, ignore, 0, 0, 3, int(lat * 1e7), int(lon * 1e7),
                                                   self.origin[2] - position[2], 1.0, 1.0, 0, 0, 0, 0, 0, 0, 10)
            self.sent += 1
        except OSError as exc:
            log.debug("feedback %s: %s", self.name, exc)

    def close(self) -> None:
        self.scheduler.cancel(self.timer)
        self.connection.close()
