"""Applications in virtual time: a scene's ``apps:`` run in-process on the model's clock, so a seed
gives the same run byte for byte.  Each gets a :class:`VirtualContext`; its links send through their
simulated modems as the GLI would (the link's packet class, its addressing) and what the modems
deliver comes back as :class:`~hilgate.core.application.Message`."""

from __future__ import annotations

import copy
import logging
from typing import Any, Callable

from ..core.application import Application, ContextBase, Message
from ..core.backend import AppFrame
from ..core.packets import PacketError, packet_class
from ..models.controlled import Controlled
from ..models.frame import BROADCAST
from .world import World, random_stream

log = logging.getLogger(__name__)

__all__ = ["VirtualApps", "VirtualContext"]


class _VirtualLink:
    def __init__(self, world: World, link_id: str):
        spec = world.scene.links[link_id]
        self.world = world
        self.id = link_id
        self.spec = spec
        self.packet = packet_class(spec.packet)
        self.modem = world.modems[link_id]
        self.seq = 0

    @property
    def address(self) -> int:
        return self.modem.address

    def send(self, payload: bytes, dst: int = BROADCAST) -> None:
        if not 0 <= dst <= 255:
            raise ValueError("dst must be 0..255 (255 broadcasts)")
        payload = bytes(payload)
        real = self.packet.encode(payload, src=self.address, dst=dst)  # PacketError if it does not fit
        limits = self.spec.limits  # what the real modem would take (the preset's limits:), as hilgate run
        problem = limits.refusal(len(real)) if limits is not None else None
        if problem is not None:
            raise PacketError("size", problem)
        self.seq = (self.seq + 1) & 0xFFFFFFFF
        modem, clock = self.modem, self.world.clock
        frame = AppFrame(real, payload, self.packet, self.seq, self.address, dst, clock.now())
        on_air = BROADCAST if self.spec.everyone_in_range else dst
        target = self.world.scene.link_of_address(modem.tx_channel, on_air)
        name = "*" if on_air == BROADCAST else (target.id if target is not None else f"addr:{on_air}")
        modem.send(modem.new_frame(name, on_air, len(real), app_frame=frame))


class _VirtualVehicle:
    def __init__(self, world: World, name: str):
        if name not in world.poses:
            raise KeyError(f"no vehicle {name!r} in the scene")
        self.world = world
        self.name = name

    def pose(self) -> tuple[float, float, float] | None:
        return self.world.poses[self.name].position(self.world.clock.now())

    def _controlled(self) -> Controlled:
        pose = self.world.poses[self.name]
        if not isinstance(pose, Controlled):
            raise TypeError(f"vehicle {self.name!r} is not controlled by applications (pose: controlled)")
        return pose

    def goto(self, position: Any) -> None:
        self._controlled().go_to(self.world.clock.now(), tuple(float(v) for v in position))
        self.world.medium.topology_changed()

    def velocity(self, velocity: Any) -> None:
        self._controlled().set_velocity(self.world.clock.now(), tuple(float(v) for v in velocity))
        self.world.medium.topology_changed()

    def stop(self) -> None:
        self._controlled().stop(self.world.clock.now())
        self.world.medium.topology_changed()


class VirtualContext(ContextBase):
    def __init__(self, world: World, spec: Any, app: Application):
        self.world = world
        self.clock = world.clock
        self.app = app
        self.name = spec.name
        self.links = spec.links
        self.params = copy.deepcopy(spec.params)  # (an application may change its own; the scene keeps its)
        self.random = random_stream(world.seed, "app", spec.name)
        self.log = logging.getLogger(f"hilgate.app.{spec.name}")
        self._links = {link_id: _VirtualLink(world, link_id) for link_id in spec.links}
        self._vehicles: dict[str, _VirtualVehicle] = {}

    def vehicle(self, name: str) -> _VirtualVehicle:
        if name not in self._vehicles:
            self._vehicles[name] = _VirtualVehicle(self.world, name)
        return self._vehicles[name]


class VirtualApps:
    """The scene's applications on a :class:`World`: started at its start, stopped at the run's end."""

    def __init__(self, world: World):
        self.world = world
        self.contexts: list[VirtualContext] = []
        listeners: dict[str, list[VirtualContext]] = {}
        for spec in world.scene.apps:
            context = VirtualContext(world, spec, spec.cls())
            self.contexts.append(context)
            for link_id in spec.links:
                listeners.setdefault(link_id, []).append(context)
        for link_id, contexts in listeners.items():
            world.modems[link_id].on_deliver = self._deliverer(link_id, contexts)

    def _deliverer(self, link_id: str, contexts: list[VirtualContext]) -> Callable[[Any], None]:
        clock = self.world.clock

        def deliver(frame: Any) -> None:
            app_frame = frame.app_frame
            if not isinstance(app_frame, AppFrame):
                return  # a flow's frame: background traffic, nothing an application reads
            message = Message(link_id, app_frame.src, app_frame.dst, clock.now(), bytes(app_frame.payload))
            for context in contexts:
                context.app.on_receive(context, message)

        return deliver

    def start(self) -> None:
        for context in self.contexts:
            self.world.clock.at(self.world.clock.now(), context.app.on_start, context)

    def stop(self) -> None:
        for context in self.contexts:
            context.app.on_stop(context)
