"""UWSim-NET's third experiment as applications (hilgate.app): the same classes run in virtual time
(``hilgate sim examples/formation/formation-virtual.yaml``) and against the daemon (``hilgate app``).

- ``Operator`` (the buoy) sends the leader its next waypoint every ``repeat_s`` (acoustic messages get
  lost), one leg of the square every ``leg_s``.
- ``Leader`` steers its vehicle to each waypoint it hears when the vehicle is ``controlled`` (in
  virtual time; with a real BlueROV its autopilot flies the route) and broadcasts its position every
  ``period_s``.
- ``Follower`` steers its vehicle to its ``slot`` relative to the last leader position it heard.
"""

import json

from hilgate.app import Application

ROUTE = [[0, 0, 2], [3, 0, 2], [3, 3, 2], [0, 3, 2]]


class Operator(Application):
    def on_start(self, ctx):
        self.legs = int(ctx.params.get("legs", 3))
        self.leg = 0
        self.next_leg(ctx)

    def next_leg(self, ctx):
        self.leg += 1
        if self.leg > self.legs:
            return
        self.until = ctx.now() + float(ctx.params.get("leg_s", 12.0))
        self.send(ctx)
        ctx.after(float(ctx.params.get("leg_s", 12.0)), self.next_leg)

    def send(self, ctx):
        if ctx.now() >= self.until - 1e-9:
            return
        waypoint = ROUTE[self.leg]
        ctx.link(ctx.links[0]).send(json.dumps({"wp": waypoint}).encode(), dst=int(ctx.params.get("leader", 1)))
        # a person (or a script's sleep) is never exactly periodic; in virtual time exact periods of two
        # applications would meet on the same instants again and again and collide every time
        ctx.after(float(ctx.params.get("repeat_s", 2.0)) + ctx.random.uniform(0.0, 0.2), self.send)


class Leader(Application):
    def on_start(self, ctx):
        self.vehicle = ctx.vehicle(ctx.params.get("vehicle", "leader"))
        self.steer = True
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
        if self.steer:
            try:
                self.vehicle.goto(waypoint)
            except Exception as exc:  # a real vehicle: its autopilot flies the route
                ctx.log.info("not steering %s: %s", ctx.params.get("vehicle", "leader"), exc)
                self.steer = False


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
