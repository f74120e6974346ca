"""A BlueROV2's pose from ArduSub over MAVLink 2 (pymavlink), and the camera's pose fed back to it.

:class:`MavlinkSource` reads in its own thread (pymavlink blocks) and hands every measurement to the
daemon's loop.  What it uses, in ArduSub's terms (``shared/protocols/s100-mavlink-aruco.md``):
``LOCAL_POSITION_NED`` (x, y, z and velocities, relative to the EKF origin) and ``ATTITUDE`` when the
vehicle sends them; else ``GLOBAL_POSITION_INT`` around a configured origin; else, with no origin,
the depth alone (``relative_alt``, negative under water).  In a bare tank ArduSub sends no
LOCAL_POSITION_NED at all, which is why a camera (merge) often gives x and y.  A silent or vanished
endpoint is not an error: the pose goes stale and the connection is retried.

It sends the vehicle nothing the scene did not ask for (:mod:`hilgate.drivers.mavlink_identity`
says why, and who hilgate is when it sends): a HEARTBEAT only with ``heartbeat`` (for routers and
autopilots that stream only to endpoints they have heard from), message-rate requests
(``MAV_CMD_SET_MESSAGE_INTERVAL``, on the autopilot's first heartbeat) only with ``message_rates``.

:class:`Feedback` sends the vehicle's position back as ``VISION_POSITION_ESTIMATE`` (ArduPilot's
ExternalNav) or ``GPS_INPUT`` around an origin (what the UWSim-NET authors did), so a real BlueROV can
hold station in a tank without GPS.
"""

from __future__ import annotations

import logging
import math
import os
import time
from typing import Any, Callable

os.environ.setdefault("MAVLINK20", "1")  # before pymavlink is imported: MAVLink 2 framing
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")
from pymavlink import mavutil  # noqa: E402

from .mavlink_identity import Identity, identity_problem  # noqa: E402
from .reader_thread import ReaderThread  # noqa: E402

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


class MavlinkSource(ReaderThread):
    """Feeds ``deliver(position, velocity, attitude)`` (called from this source's thread; make it
    thread-safe) with what the vehicle reports."""

    def __init__(self, name: str, url: str, deliver: Callable[..., Any], system_id: int | None = None,
                 origin: tuple[float, float, float] | None = None, message_rates: tuple = (),
                 heartbeat: Identity | None = None, heartbeat_hz: float = 1.0):
        """``heartbeat``: who to send HEARTBEATs as (None: send none); ``system_id``: only this vehicle."""
        problem = identity_problem(heartbeat) if heartbeat is not None else None
        if problem:
            raise ValueError(f"mavlink {name}: heartbeat: {problem}")
        self.name = name
        self.url = url
        self.deliver = deliver
        self.system_id = system_id
        self.origin = origin
        self.message_rates = dict(message_rates)
        self.heartbeat = heartbeat
        self.heartbeat_period = 1.0 / heartbeat_hz
        self.messages = 0
        super().__init__(f"mavlink-{name}")
        self._last_local = -math.inf
        self._asked = False

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                me = self.heartbeat or Identity(self.system_id or 1)  # what pymavlink stamps; sent only if asked
                connection = mavutil.mavlink_connection(self.url, source_system=me.system_id,
                                                        source_component=me.component_id)
            except Exception as exc:  # any pymavlink/OS error: the endpoint is not there yet
                log.warning("mavlink %s: cannot open %s (%s); retrying", self.name, self.url, exc)
                self._stop.wait(2.0)
                continue
            try:
                self._serve(connection)
            except Exception as exc:
                log.warning("mavlink %s: %s; reconnecting", self.name, exc)
                self._stop.wait(1.0)
            finally:
                try:
                    connection.close()
                except Exception:
                    pass

    def _serve(self, connection: Any) -> None:
        last_beat = -math.inf
        while not self._stop.is_set():
            now = time.monotonic()
            if self.heartbeat is not None and now - last_beat >= self.heartbeat_period:
                last_beat = now
                try:  # an onboard peripheral's heartbeat, never a ground station's
                    connection.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                                  mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                                  mavutil.mavlink.MAV_STATE_ACTIVE)
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
            if message.autopilot != mavutil.mavlink.MAV_AUTOPILOT_INVALID and self.message_rates and not self._asked:
                self._asked = True  # the autopilot's (not a ground station's or a companion's) first heartbeat
                self._ask_rates(connection, message.get_srcSystem(), message.get_srcComponent())
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

    def _ask_rates(self, connection: Any, system: int, component: int) -> None:
        """SET_MESSAGE_INTERVAL for each of ``message_rates``, sent as the heartbeat's identity or, with
        none, as a companion computer of the vehicle (its system id, hilgate's own component)."""
        me = self.heartbeat or Identity(system)
        problem = identity_problem(me)
        if problem:
            log.warning("mavlink %s: not asking for message rates: %s", self.name, problem)
            return
        connection.mav.srcSystem, connection.mav.srcComponent = me.system_id, me.component_id
        for name, rate in self.message_rates.items():
            # by name: the message the scene names, by its name
            message_id = getattr(mavutil.mavlink, f"MAVLINK_MSG_ID_{name.upper()}", None)
            if message_id is None:
                log.warning("mavlink %s: unknown message %s in message_rates", self.name, name)
                continue
            connection.mav.command_long_send(system, component, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                             message_id, 1e6 / rate, 0, 0, 0, 0, 0)


class Feedback:
    """Sends a vehicle's board position to its autopilot at ``rate_hz`` (from the daemon's loop), as
    ``identity`` (default: a companion computer of the vehicle ``system_id``, which ArduPilot accepts
    even with SYSID_ENFORCE, with hilgate's own component id)."""

    def __init__(self, name: str, url: str, message: str, rate_hz: float, origin, system_id: int,
                 position: Callable[[], tuple | None], attitude: Callable[[], tuple | None], scheduler: Any,
                 identity: Identity | None = None):
        identity = identity or Identity(system_id)
        problem = identity_problem(identity)
        if problem:
            raise ValueError(f"feedback {name}: {problem}")
        self.name = name
        self.message = message
        self.period = 1.0 / rate_hz
        self.origin = origin
        self.target = system_id
        self.position = position
        self.attitude = attitude
        self.scheduler = scheduler
        self.sent = 0
        self.connection = mavutil.mavlink_connection(url, source_system=identity.system_id,
                                                     source_component=identity.component_id)
        self.timer = scheduler.after_wall(self.period, self._tick)

    def _tick(self) -> None:
        self.timer = self.scheduler.after_wall(self.period, self._tick)
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


def start_pose_feed(setting: Any, params: dict) -> MavlinkSource:
    """The ``mavlink`` row of the pose-source table (:mod:`hilgate.scene.pose_table`): a vehicle's
    autopilot read on a thread of its own, each measurement posted to the loop."""
    from .mavlink_identity import Identity

    heartbeat = dict(params["heartbeat"] or ())
    identity = Identity(heartbeat["system_id"], heartbeat["component_id"]) if heartbeat else None
    source = MavlinkSource(setting.vehicle, params["url"], setting.posting("mavlink"), params["system_id"],
                           params["origin"], params["message_rates"], identity, heartbeat.get("rate_hz", 1.0))
    source.start()
    return source
