"""Ping and pong: the application API's complete example (docs/applications.md).

``Ping`` sends a numbered ping every ``period_s`` to ``peer`` and logs each pong's round trip;
``Pong`` answers every ping.  The same classes run in virtual time (``hilgate sim
examples/apps/pingpong.yaml``) and against a running daemon (``hilgate app
examples/apps/pingpong.py:Pong --link b`` and ``... :Ping --link a``)."""

from hilgate.app import Application


class Ping(Application):
    def on_start(self, ctx):
        self.number = 0
        self.sent = {}  # number → when it was sent, until its pong comes
        self.round_trips = []
        self.timer = ctx.every(float(ctx.params.get("period_s", 10.0)), self.ping)

    def ping(self, ctx):
        if self.number >= int(ctx.params.get("count", 1_000_000)):
            ctx.cancel(self.timer)
            return
        self.number += 1
        number = self.number
        jitter = ctx.random.uniform(0.0, float(ctx.params.get("jitter_s", 0.0)))
        ctx.after(jitter, self.send, number)

    def send(self, ctx, number):
        self.sent[number] = ctx.now()
        ctx.link(ctx.links[0]).send(b"ping %d" % number, dst=int(ctx.params.get("peer", 255)))

    def on_receive(self, ctx, message):
        if message.data.startswith(b"pong "):
            number = int(message.data.split()[1])
            if number in self.sent:
                self.round_trips.append(ctx.now() - self.sent.pop(number))
                ctx.log.info("pong %d after %.3f s", number, self.round_trips[-1])

    def on_stop(self, ctx):
        ctx.log.info("%d round trips, %d pings unanswered", len(self.round_trips), len(self.sent))


class Pong(Application):
    def on_receive(self, ctx, message):
        if message.data.startswith(b"ping "):
            ctx.link(message.link).send(b"pong " + message.data.split()[1], dst=message.src)
