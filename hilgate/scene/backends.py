"""The link keys that the backend table decides: ``backend:``, a real driver's options, ``emulate:``.

Everything driver-specific is read from :mod:`hilgate.drivers.table` each time a link is read: which
backends exist, which keys each takes and how each is checked, which one is required (and what to
give), which protocols can be emulated and which of them over TCP.  So a modem type added to the
table is a valid backend here, with its keys, its checks, its "only for backend X" and its place in
"did you mean", without a line changed in the loader.  The table imports no driver; the only driver
code run here is :func:`hilgate.drivers.port.port_problem`, when a scene names a port.
"""

from __future__ import annotations

import re
from typing import Any

from ..drivers.table import DRIVERS, Option, emulated_protocols, emulator_options, scene_options
from .checks import Checker, Fields, boolean, choice, integer, number, path_value, pty_path, text
from .yaml_nodes import Node

__all__ = ["backend_names", "driver_keys", "driver_options", "emulated_device"]

SIM = "sim"  # the simulated modem: not a driver, opened by the world


def backend_names() -> tuple[str, ...]:
    return (SIM, *DRIVERS)


def driver_keys() -> tuple[str, ...]:
    """Every driver's scene keys, each once, in the table's order (for unknown-key messages)."""
    return tuple(dict.fromkeys(key for driver in DRIVERS.values() for key, _, _ in scene_options(driver)))


def driver_options(f: Fields, backend: str) -> tuple[tuple[str, Any], ...]:
    """The driver keys a link gives, checked: none unless its backend takes them, its required ones
    present.  Returns (key, value) in the order the driver declares them."""
    driver = DRIVERS.get(backend)
    declared = list(scene_options(driver)) if driver is not None else []
    allowed = [key for key, _, _ in declared]
    for key in driver_keys():
        if key in f and key not in allowed:
            users = [name for name, other in DRIVERS.items() if key in (k for k, _, _ in scene_options(other))]
            raise f.child(key).error(f.sub(key), f"only for backend {' or '.join(users)} (this link is {backend})")
    for key, check, required in declared:
        if required and key not in f:
            raise f.error(f"backend {backend} needs {key!r}" + (f" ({check.hint})" if check.hint else ""))
    return tuple((key, f.get(key, checker(check))) for key, check, _ in declared if key in f)


def checker(option: Option) -> Checker:
    """The scene checker of one driver option, from the table's metadata."""
    if option.kind == "port":
        return _port
    if option.kind == "integer":
        low = None if option.minimum is None else int(option.minimum)
        high = None if option.maximum is None else int(option.maximum)
        return integer(low, high)
    if option.kind == "number":
        return number(option.minimum, option.maximum, above=option.above)
    if option.kind == "boolean":
        return boolean
    if option.kind == "host":
        return _host
    return choice(*option.choices)


HOST = re.compile(r"[A-Za-z0-9]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?|\[?[0-9A-Fa-f:.]+\]?")


def _host(node: Node, path: str) -> str:
    """A host name or an IP address (looked up when the driver connects, not when the scene loads)."""
    value = text(node, path)
    if not HOST.fullmatch(value):
        raise node.error(path, f"{value[:100]!r} is not a host name or an IP address")
    return value.strip("[]")


def _port(node: Node, path: str) -> str:
    """A device path (relative to the scene) or a pyserial URL that hilgate can open."""
    from ..drivers.port import port_problem

    value = node.value
    problem = port_problem(value) if isinstance(value, str) and value else None
    if problem:
        raise node.error(path, problem)
    value = text(node, path)
    return value if "://" in value else path_value(node, path)


def emulated_device(node: Node, path: str) -> tuple[tuple[str, Any], ...]:
    """``emulate: {protocol, pty | tcp, <the device's own options>}``: an emulated device in front of a
    simulated link (its own options, e.g. the S100's ``baud``, come from the backend table)."""
    own = {name: list(emulator_options(driver)) for name, driver in DRIVERS.items()}
    keys = tuple(dict.fromkeys(key for options in own.values() for key, _, _ in options))
    f = Fields(node, path, ("protocol", "pty", "tcp", *keys))
    protocol = f.get("protocol", choice(*emulated_protocols()))
    _refuse_others_options(f, own, keys, protocol)
    extra = tuple((key, f.get(key, checker(check)) if key in f else default) for key, check, default in own[protocol])
    if ("pty" in f) == ("tcp" in f):
        raise f.error("give exactly one of pty (a path for the device link) or tcp (a loopback port)")
    if "pty" in f and not DRIVERS[protocol].emulator_pty:
        raise f.child("pty").error(f.sub("pty"), f"the {DRIVERS[protocol].title} speaks TCP only: give tcp (a loopback port)")
    if "tcp" in f:
        if not DRIVERS[protocol].emulator_tcp:
            speakers = " or the ".join(d.title for d in DRIVERS.values() if d.emulator and d.emulator_tcp)
            raise f.child("tcp").error(f.sub("tcp"), f"only the {speakers} speaks TCP; "
                                                     f"the {DRIVERS[protocol].title} is serial")
        return (("protocol", protocol), ("tcp", f.get("tcp", integer(1, 65535))), *extra)
    return (("protocol", protocol), ("pty", f.get("pty", pty_path)), *extra)


def _refuse_others_options(f: Fields, own: dict[str, list], keys: tuple[str, ...], protocol: str) -> None:
    """An error at the first of ``keys`` given that is another emulated device's option, not ``protocol``'s
    (``own``: each protocol's options), naming the protocols it is for."""
    for key in keys:
        if key in f and key not in (k for k, _, _ in own[protocol]):
            users = [name for name, options in own.items() if key in (k for k, _, _ in options)]
            raise f.child(key).error(f.sub(key), f"only for protocol {' or '.join(users)} (this is {protocol})")
