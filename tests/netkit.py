"""Tiny networks built straight from the models, for exact timing tests."""

from __future__ import annotations

import random

from hilgate.models.frame import BROADCAST, Frame
from hilgate.models.medium import Channel, Medium
from hilgate.models.modem import ModemParams, SimModem
from hilgate.models.observer import EventList
from hilgate.models.trajectories import Static
from hilgate.core.scheduler import VirtualScheduler


class Net:
    def __init__(self, *channels: Channel, seed: int = 1):
        self.clock = VirtualScheduler()
        self.medium = Medium(self.clock, channels or [Channel("ch", 1500.0)])
        self.events = EventList()
        self.modems: dict[str, SimModem] = {}
        self.seed = seed
        self.delivered: dict[str, list[tuple[float, Frame]]] = {}

    def modem(self, name: str, pose=(0, 0, 0), address: int | None = None, mac=None, **params) -> SimModem:
        channel = params.pop("channel", next(iter(self.medium.channels)))
        params.setdefault("tx_channel", channel)
        params.setdefault("rx_channel", channel)
        address = len(self.modems) + 1 if address is None else address
        source = pose if hasattr(pose, "position") else Static(pose)
        modem = SimModem(name, name, source, ModemParams(address=address, **params), self.clock, self.medium,
                         random.Random(f"{self.seed}/{name}"), self.events, mac)
        self.modems[name] = modem
        self.delivered[name] = []
        modem.on_deliver = lambda frame, name=name: self.delivered[name].append((self.clock.now(), frame))
        return modem

    def send(self, src: str, dst: str | None, size: int, at: float | None = None) -> Frame:
        sender = self.modems[src]
        dst_addr = BROADCAST if dst is None else self.modems[dst].address
        frame = Frame(next(self.medium.frame_ids), src, dst or "*", dst_addr, size, 0.0)

        def go():
            frame.t0 = self.clock.now()
            sender.send(frame)

        if at is None:
            go()
        else:
            self.clock.at(at, go)
        return frame

    def run(self, until: float = float("inf")) -> None:
        self.clock.run(until)

    def lost_of(self, src: str, dst: str, n: int, size: int) -> int:
        """Send ``n`` frames of ``size`` bytes from ``src`` to ``dst``, one a second, run, and count those
        ``dst`` lost (every frame is either received or lost there)."""
        for i in range(n):
            self.send(src, dst, size, at=i * 1.0)
        self.run()
        lost = len(self.of("err", dst))
        assert len(self.of("rx", dst)) + lost == n
        return lost

    def of(self, ev: str, link: str | None = None):
        return [e for e in self.events.of(ev) if link is None or e[2] == link]
