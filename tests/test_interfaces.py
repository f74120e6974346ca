"""Every seam a plug-in or another room uses is a declared interface, and every implementation in the
product satisfies it: its members, and methods that take what the interface passes.

A new implementation is found without being listed: a product class that defines every method of an
interface looks like one of its implementations, and must be listed here (and so checked)."""

import importlib
import inspect
import os
import pkgutil

import pytest

import hilgate
from hilgate.core.backend import Backend
from hilgate.core.endpoint import Door, Endpoint, LinkPort, Measurements
from hilgate.core.unet_node import NodeHost
from hilgate.core.scheduler import Loop, Scheduler
from hilgate.daemon.live_sources import PoseFeed
from hilgate.models.clock import Clock
from hilgate.models.mac import MacHost
from hilgate.models.observer import Observer
from hilgate.models.propagation import Propagation
from hilgate.models.radio import LossModel, RadioHost, SinrLossModel
from hilgate.models.trajectories import PoseSource
from seamcheck import members, missing

# interface → its implementations in the product ("module:Class")
SEAMS = {
    Endpoint: ["hilgate.gli.queues:MqEndpoint", "hilgate.gli.sockets:GliClient",
               "hilgate.gli.zenoh_door:ZenohEndpoint", "hilgate.drivers.evologics_emulator:EvologicsEmulator",
               "hilgate.drivers.s100_emulator:S100Emulator", "hilgate.drivers.m64_emulator:M64Emulator",
               "hilgate.drivers.micromodem_emulator:MicromodemEmulator", "hilgate.ros2.door:Ros2Endpoint",
               "hilgate.gli.unet_door:UnetEndpoint", "hilgate.drivers.unet_emulator:UnetEmulator"],
    Door: ["hilgate.gli.queues:QueueDoor", "hilgate.gli.sockets:SocketDoor", "hilgate.gli.zenoh_door:ZenohDoor",
           "hilgate.drivers.emulators:EmulatorDoor", "hilgate.ros2.door:Ros2Door", "hilgate.daemon.ros2_bridge:Ros2Bridge",
           "hilgate.gli.unet_door:UnetDoor"],
    NodeHost: ["hilgate.core.unet_server:NodeServer", "hilgate.gli.unet_door:UnetEndpoint",
               "hilgate.drivers.unet_emulator:UnetEmulator"],
    LinkPort: ["hilgate.daemon.routed_link:RoutedLink"],
    Measurements: ["hilgate.sim.measurements:ModemMeasurements"],
    RadioHost: ["hilgate.models.modem:SimModem"],
    MacHost: ["hilgate.models.modem:SimModem"],
    PoseSource: ["hilgate.models.trajectories:Static", "hilgate.models.trajectories:Piecewise",
                 "hilgate.models.controlled:Controlled", "hilgate.sim.live_vehicle:LiveVehicle",
                 "hilgate.sim.live_vehicle:RemoteVehicle"],
    PoseFeed: ["hilgate.drivers.mavlink_source:MavlinkSource", "hilgate.drivers.aruco:CameraThread",
               "hilgate.ros2.poses:Ros2PoseFeed"],
    Clock: ["hilgate.core.scheduler:VirtualScheduler", "hilgate.core.realtime:RealtimeScheduler"],
    Scheduler: ["hilgate.core.scheduler:VirtualScheduler", "hilgate.core.realtime:RealtimeScheduler"],
    Loop: ["hilgate.core.realtime:RealtimeScheduler"],
    Observer: ["hilgate.models.observer:NullObserver", "hilgate.models.observer:EventList",
               "hilgate.sim.recorder:Recorder"],
    LossModel: ["hilgate.models.errormodel:ErrorModel", "hilgate.models.physical:PhysicalErrorModel",
                "hilgate.models.bellhop_fields:BellhopPath", "hilgate.models.bellhop_fields:ArrivalLoss",
                "hilgate.models.path:Unheard",
                "hilgate.models.path:Undecodable", "hilgate.models.neighbours:_Neighbour"],
    SinrLossModel: ["hilgate.models.physical:PhysicalErrorModel", "hilgate.models.path:Undecodable",
                    "hilgate.models.bellhop_fields:BellhopPath", "hilgate.models.bellhop_fields:ArrivalLoss",
                    "hilgate.models.path:Unheard",
                    "hilgate.models.neighbours:_Neighbour"],
}
SEAMS[Propagation] = ["hilgate.models.propagation:StraightLine", "hilgate.models.bellhop_fields:BellhopChannel"]
BACKENDS = ["hilgate.sim.sim_backend:SimBackend", "hilgate.drivers.evologics:EvologicsBackend",
            "hilgate.drivers.s100:S100Backend", "hilgate.drivers.m64:M64Backend",
            "hilgate.drivers.micromodem:MicromodemBackend", "hilgate.drivers.unet:UnetBackend"]


def load(name):
    module, _, attribute = name.partition(":")
    return getattr(importlib.import_module(module), attribute)


CASES = [(protocol, name) for protocol, names in SEAMS.items() for name in names]


@pytest.mark.parametrize("protocol,name", CASES, ids=[f"{p.__name__}-{n.rpartition(':')[2]}" for p, n in CASES])
def test_every_implementation_satisfies_its_interface(protocol, name):
    assert missing(load(name), protocol) == []


@pytest.mark.parametrize("name", BACKENDS, ids=lambda n: n.rpartition(":")[2])
def test_every_backend_is_a_complete_backend(name):
    """Backends share a base class: its optional capabilities have the defaults of a backend without them."""
    cls = load(name)
    assert issubclass(cls, Backend) and not inspect.isabstract(cls)


def test_the_checker_sees_what_is_missing():
    """The check itself can fail: a missing member, a method that takes too little or requires too much."""

    class NoState:
        kind = "x"
        busy = False
        assumes_busy = False
        phy = None

        def deliver(self, frame, t):
            return "taken"

        def close(self, now):  # requires an argument the link never passes
            pass

    problems = missing(NoState, Endpoint)
    assert any(p.endswith("state: missing (Endpoint declares it)") for p in problems)
    assert any("close: requires now" in p for p in problems)

    class ShortDeliver(NoState):
        def deliver(self, frame):
            return "taken"

        def state(self, ready):
            pass

        def close(self):
            pass

    assert [p.split(": ", 1)[1] for p in missing(ShortDeliver, Endpoint)] == ["takes no argument 't' (position 2)"]


def product_classes():
    root = os.path.dirname(hilgate.__file__)
    for package in ("hilgate", "hilgate.models", "hilgate.drivers"):
        path = importlib.import_module(package).__path__
        for info in pkgutil.walk_packages(path, package + "."):
            if info.name.endswith("__main__"):
                continue
            module = importlib.import_module(info.name)
            for value in vars(module).values():
                if inspect.isclass(value) and value.__module__ == info.name:
                    yield f"{info.name}:{value.__name__}", value
    del root


def test_a_class_that_looks_like_an_implementation_is_listed():
    listed = {protocol: set(names) for protocol, names in SEAMS.items()}
    unlisted = []
    for name, cls in product_classes():
        if getattr(cls, "_is_protocol", False):
            continue
        for protocol in SEAMS:
            methods = {n for n, v in members(protocol).items() if inspect.isfunction(v)}
            if len(methods) >= 3 and all(inspect.isfunction(getattr(cls, m, None)) for m in methods) \
                    and name not in listed[protocol]:
                unlisted.append(f"{name} looks like a {protocol.__name__}: list it in SEAMS")
    assert unlisted == []


def test_no_member_is_looked_up_by_name_without_saying_why():
    """A seam is declared, not discovered: what still looks a member up by name (a class a scene names,
    the fields of a dataclass, a platform's constant) says why on its line or the line above."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    silent = []
    for folder in ("hilgate", "models", "drivers"):
        for dirpath, _, files in os.walk(os.path.join(root, folder)):
            for name in files:
                if not name.endswith(".py"):
                    continue
                path = os.path.join(dirpath, name)
                lines = open(path, encoding="utf-8").read().splitlines()
                for number, line in enumerate(lines):
                    if "hasattr(" in line or "getattr(" in line:
                        if "#" not in line and not (number and lines[number - 1].strip().startswith("#")):
                            silent.append(f"{os.path.relpath(path, root)}:{number + 1}: {line.strip()}")
    assert silent == []
