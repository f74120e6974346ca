"""A scene made live: pose sources, the medium, one simulated modem per ``sim`` link, and flows.

The same :class:`World` serves ``hilgate sim`` (virtual clock) and the daemon (real-time clock).
Every random stream is derived from the scene seed and the name of what uses it, so adding a flow
does not change the backoffs of a modem, and a seed gives the same run byte for byte.
"""

from __future__ import annotations

import random
from typing import Any

from .models.flows import FlowSource
from .models.frame import BROADCAST
from .models.medium import Medium
from .models.modem import SimModem
from .models.observer import Observer
from .models.trajectories import PoseSource
from .poses import build_pose
from .scene import LinkSpec, Scene


def random_stream(seed: int, *names: str) -> random.Random:
    """A reproducible random stream per user (string seeds are hashed with SHA-512 by ``random``)."""
    return random.Random("/".join([str(seed), *names]))


class World:
    def __init__(self, scene: Scene, clock: Any, observer: Observer, seed: int | None = None):
        self.scene = scene
        self.clock = clock
        self.observer = observer
        self.seed = scene.seed if seed is None else seed
        self.medium = Medium(clock, scene.channels.values())
        self.poses: dict[str, PoseSource] = {name: build_pose(v.pose) for name, v in scene.vehicles.items()}
        self.modems: dict[str, SimModem] = {}
        for link in scene.links.values():
            if link.backend == "sim":
                self.add_modem(link)
        self.flows: list[FlowSource] = []
        for index, spec in enumerate(scene.flows):
            modem = self.modems.get(spec.src)
            if modem is None:
                continue
            dst_addr = BROADCAST if spec.dst == "*" else scene.links[spec.dst].params.address
            stats = observer.add_flow(spec) if hasattr(observer, "add_flow") else None
            self.flows.append(
                FlowSource(spec, modem, dst_addr, clock, random_stream(self.seed, "flow", str(index)), stats)
            )

    def add_modem(self, link: LinkSpec) -> SimModem:
        modem = SimModem(
            link.id, link.vehicle, self.poses[link.vehicle], link.params, self.clock, self.medium,
            random_stream(self.seed, "modem", link.id), self.observer, link.mac.build(),
        )
        self.modems[link.id] = modem
        return modem

    def start(self) -> None:
        for flow in self.flows:
            flow.start()
