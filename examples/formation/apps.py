"""UWSim-NET's third experiment as applications (hilgate.app): the same classes run in virtual time
(``hilgate sim scenes/paper-exp3-formation-virtual.yaml``) and against the daemon (``hilgate app``).

- ``Operator`` (the buoy) sends the leader its next waypoint every ``repeat_s`` (acoustic messages get
  lost), one leg of the ``route`` (a scene parameter; the 3 m square by default) every ``leg_s``.
- ``Leader`` steers its vehicle to each waypoint it hears when the vehicle is ``controlled`` (in
  virtual time); with a real or fake BlueROV (``autopilot: udpout:HOST:PORT``) it passes each waypoint to
  the autopilot as MAVLink SET_POSITION_TARGET_LOCAL_NED, as ``leader.py`` does. Either way it
  broadcasts its position every ``period_s``.
- ``Follower`` steers its vehicle to its ``slot`` relative to the last leader position it heard.
"""

import json

from hilgate.app import Application

ROUTE = [[0, 0, 2], [3, 0, 2], [3, 3, 2], [0, 3, 2]]


class Operator(Application):
    def on_start(self, ctx):
        self.route = [[float(v) for v in point] for point in ctx.params.get("route", ROUTE)]
        self.legs = min(int(ctx.params.get("legs", len(self.route) - 1)), len(self.route) - 1)
        self.leg = 0
        self.pending = None  # the next repetition of the current leg's waypoint
        self.next_leg(ctx)

    def next_leg(self, ctx):
        self.leg += 1
        if self.pending is not None:  # one waypoint at a time: the last leg's repetitions end here
            ctx.cancel(self.pending)
            self.pending = None
        if self.leg > self.legs:
            return
        self.until = ctx.now() + float(ctx.params.get("leg_s", 12.0))
        self.send(ctx)
        ctx.after(float(ctx.params.get("leg_s", 12.0)), self.next_leg)

    def send(self, ctx):
        self.pending = None
        if ctx.now() >= self.until - 1e-9:
            return
        waypoint = self.route[self.leg]
        ctx.link(ctx.links[0]).send(json.dumps({"wp": waypoint}).encode(), dst=int(ctx.params.get("leader", 1)))
        # a person (or a script's sleep) is never exactly periodic; in virtual time exact periods of two
        # applications would meet on the same instants again and again and collide every time
        self.pending = ctx.after(float(ctx.params.get("repeat_s", 2.0)) + ctx.random.uniform(0.0, 0.2), self.send)


class Leader(Application):
    def on_start(self, ctx):
        self.vehicle = ctx.vehicle(ctx.params.get("vehicle", "leader"))
        self.steer = True
        self.autopilot = None
        if ctx.params.get("autopilot"):  # a vehicle with its own autopilot: only hilgate app gets here
            self.autopilot = Autopilot(str(ctx.params["autopilot"]), int(ctx.params.get("system_id", 1)))
            self.steer = False
        period = float(ctx.params.get("period_s", 1.0))
        ctx.after(ctx.random.uniform(0.0, period), lambda ctx: ctx.every(period, self.broadcast))  # its own phase

    def broadcast(self, ctx):
        position = self.vehicle.pose()
        if position is not None:
            ctx.link(ctx.links[0]).send(json.dumps({"leader": [round(v, 2) for v in position]}).encode())

    def on_receive(self, ctx, message):
        try:
            waypoint = json.loads(message.data)["wp"]
        except (ValueError, KeyError, TypeError):
            return
        if self.autopilot is not None:
            self.autopilot.goto(waypoint)
        elif self.steer:
            try:
                self.vehicle.goto(waypoint)
            except Exception as exc:  # a real vehicle: its autopilot flies the route
                ctx.log.info("not steering %s: %s", ctx.params.get("vehicle", "leader"), exc)
                self.steer = False


class Autopilot:
    """The leader's companion computer speaking to ArduSub (or fake_bluerov.py): a position target in
    GUIDED mode, from the vehicle's system id and MAV_COMP_ID_ONBOARD_COMPUTER (never as the pilot's
    ground station).  pymavlink is imported here: the virtual-time run needs none of it."""

    POSITION_ONLY = 0b0000111111111000  # type_mask: use x, y, z only

    def __init__(self, url: str, system_id: int):
        import os

        os.environ.setdefault("MAVLINK20", "1")
        from pymavlink import mavutil

        self.mavutil = mavutil
        self.connection = mavutil.mavlink_connection(url, source_system=system_id,
                                                     source_component=mavutil.mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)

    def goto(self, waypoint):
        self.connection.mav.set_position_target_local_ned_send(
            0, 1, 1, self.mavutil.mavlink.MAV_FRAME_LOCAL_NED, self.POSITION_ONLY, *waypoint, 0, 0, 0, 0, 0, 0, 0, 0)


class Follower(Application):
    def on_start(self, ctx):
        self.slot = [float(v) for v in ctx.params["slot"]]
        self.vehicle = ctx.vehicle(ctx.params["vehicle"])

    def on_receive(self, ctx, message):
        try:
            leader = json.loads(message.data)["leader"]
        except (ValueError, KeyError, TypeError):
            return
        self.vehicle.goto([l + s for l, s in zip(leader, self.slot)])
