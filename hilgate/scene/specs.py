"""The typed result of loading a scene: what the world, the router and the live sources build from.

Every spec is a frozen dataclass (``Scene`` aside), so a reload compares old and new by value, and
every one pickles (a reload is validated in a worker process, :mod:`hilgate.scene.worker`).  Nothing
here reads YAML: the section modules (:mod:`.links`, :mod:`.vehicles`, :mod:`.flows`) fill these in.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..models.flows import FlowSpec
from ..models.mac import Mac
from ..models.macs import REGISTRY as MAC_REGISTRY
from ..models.medium import Channel
from ..models.modem import ModemParams
from ..models.usbl import UsblParams
from .plugins import class_from_origin, origin_of

__all__ = ["PoseSpec", "VehicleSpec", "CameraSpec", "MacSpec", "LinkSpec", "Scene"]


@dataclass(frozen=True)
class PoseSpec:
    """``kind`` names the pose source; ``params`` is what its checker returned (hashable).  For live
    vehicles ``kind`` is ``live`` and ``params`` holds ``((kind, params), …)`` of every source, with
    ``merge`` saying which source gives which axis when there are several."""

    kind: str
    params: Any
    merge: tuple[tuple[str, str], ...] = ()

    @property
    def source_name(self) -> str:
        if self.kind == "live":
            return "+".join(kind for kind, _ in self.params)
        return self.kind


@dataclass(frozen=True)
class VehicleSpec:
    name: str
    pose: PoseSpec
    line: int = field(default=0, compare=False)
    stale_after_s: float = 2.0
    stale: str = "hold"
    extrapolate_s: float = 0.0
    initial: tuple[float, float, float] | None = None
    feedback: tuple[tuple[str, Any], ...] = ()
    host: str | None = None  # the host that computes or measures its pose (scene/hosts.py)


@dataclass(frozen=True)
class CameraSpec:
    name: str
    source: int | str
    calibration: str
    dictionary: str
    marker_length_m: float
    fixed: tuple | None = None       # (position, rpy_deg) of the camera in the scene frame
    onboard: tuple | None = None     # (vehicle, position, rpy_deg) of the camera on a vehicle
    map: tuple = ()                  # ((marker id, position, rpy_deg), …) markers fixed in the tank
    fps: float | None = None
    host: str | None = None


@dataclass(frozen=True)
class MacSpec:
    """``protocol`` as the scene names it; ``cls`` is the class it named (a built-in one, or one that a
    listed plugin provides), resolved when the scene loaded so that building never imports anything."""

    protocol: str
    params: tuple[tuple[str, Any], ...] = ()
    cls: type[Mac] | None = field(default=None, compare=False, repr=False)

    @property
    def mac_class(self) -> type[Mac]:
        return self.cls or MAC_REGISTRY[self.protocol]

    def build(self) -> Mac:
        return self.mac_class(**dict(self.params))

    def __reduce__(self):
        """Pickled by name (a reload is validated in a worker process): a plugin's class is found again
        from its file or module, which the daemon loads as the scene listed it."""
        if self.cls is None or self.protocol in MAC_REGISTRY:
            return (MacSpec, (self.protocol, self.params))
        return (_plugin_mac_spec, (self.protocol, self.params, origin_of(self.cls), self.cls.__qualname__))


def _plugin_mac_spec(protocol: str, params: tuple, origin: str, qualname: str) -> MacSpec:
    cls = class_from_origin(origin, qualname)
    if not (isinstance(cls, type) and issubclass(cls, Mac)):
        raise TypeError(f"{origin}:{qualname} is not a MAC")
    return MacSpec(protocol, params, cls)


@dataclass(frozen=True)
class LinkSpec:
    id: str
    vehicle: str
    backend: str
    model: str | None
    params: ModemParams
    mac: MacSpec
    packet: str
    file: str = field(default="", compare=False)
    line: int = field(default=0, compare=False)
    options: tuple[tuple[str, Any], ...] = ()  # the driver's keys (port, baud…) for real backends
    emulate: tuple[tuple[str, Any], ...] = ()  # emulated modem in front of a sim link
    addressing: str = "auto"  # auto: address-less packet classes without a MAC reach everyone in range
    host: str | None = None  # the host whose daemon serves it (None: a scene for one daemon)
    usbl: UsblParams | None = None  # the emulated modem is a USBL: it reports fixes of whom it hears
    address_line: int = field(default=0, compare=False)  # where a wide address (> 254) is written
    gli: tuple[str, ...] = ("mq", "socket")  # the GLI endpoints the daemon opens for it (links.py)
    limits: Any = None  # drivers.table.ModemLimits: what the modem accepts (its preset's limits:), None: unsaid
    unet: tuple[tuple[str, Any], ...] = ()  # its UnetStack door: tcp, host, protocol (scene/unet_spec.py)

    @property
    def everyone_in_range(self) -> bool:
        """Frames from applications reach every modem in range whatever their virtual destination:
        UWSim-NET's behaviour for packet classes that carry no address on air, without a MAC."""
        from ..core.packets import packet_class

        return (self.addressing == "auto" and self.mac.protocol == "none"
                and not packet_class(self.packet).addresses_on_air)


@dataclass
class Scene:
    name: str
    seed: int
    duration_s: float
    channels: dict[str, Channel]
    vehicles: dict[str, VehicleSpec]
    links: dict[str, LinkSpec]
    flows: list[FlowSpec]
    trace_file: str | None
    path: str
    cameras: dict[str, CameraSpec] = field(default_factory=dict)
    trace_poses_s: float | None = 1.0  # pose samples in the trace every so many seconds (None: none)
    hosts: tuple[str, ...] = ()  # the hosts the scene names (scene/hosts.py); () for one daemon
    zenoh: Any = None  # the ``zenoh:`` section (a ZenohSpec), None when absent
    apps: tuple = ()  # the ``apps:`` hilgate sim runs in-process (scene/app_spec.py AppSpec)
    ros2: Any = None  # the ``ros2:`` section (a scene.ros2.Ros2Spec), None when absent

    @property
    def uses_ros2(self) -> bool:
        """A ``ros2:`` section, a vehicle's ``ros2`` pose or a link on ROS 2: the daemon needs a participant."""
        return (self.ros2 is not None or any("ros2" in link.gli for link in self.links.values())
                or any(kind == "ros2" for v in self.vehicles.values() if v.pose.kind == "live" for kind, _ in v.pose.params))

    @property
    def multi_host(self) -> bool:
        return bool(self.hosts) or self.zenoh is not None

    def link_of_address(self, channel: str, address: int) -> LinkSpec | None:
        for link in self.links.values():
            if link.params.rx_channel == channel and link.params.address == address:
                return link
        return None
