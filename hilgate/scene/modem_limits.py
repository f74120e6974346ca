"""A link's ``limits:``: what its modem accepts, as its preset (or the link) states it.

The figures are the backend table's :class:`~hilgate.drivers.table.ModemLimits`: a preset gives them
with their sources (``models/*.yaml``), a link may override one (``limits: {send_as: burst}``), and
what is not given is the driver's own assumption.  A driver link, an emulated modem and a simulated
link all work by the same figures, so a frame the real modem would refuse is refused everywhere with
the driver's words.  Limits of one modem on a link that drives or emulates another are refused here.
"""

from __future__ import annotations

from dataclasses import replace

from ..drivers.table import DRIVERS, SEND_AS, ModemLimits
from .checks import Fields, choice, integer
from .yaml_nodes import Node

__all__ = ["LIMIT_KEYS", "modem_limits", "describe_limits"]

LIMIT_KEYS = ("modem", "send_as", "modes", "piece_bytes", "flow_control", "baud")
MAX_BYTES = 1 << 20


def modem_limits(node: Node, path: str, backend: str, emulated: str | None) -> ModemLimits:
    """``limits: {modem, send_as, modes: {im: 64, …}, piece_bytes, flow_control, baud}``, checked against
    the modem's driver row (its modes, whether it cuts frames in pieces) and against the link: a driver
    link or an emulated modem of another type cannot take them."""
    f = Fields(node, path, LIMIT_KEYS)
    wired = backend if backend in DRIVERS else emulated
    named = [name for name, driver in DRIVERS.items() if driver.limits is not None]
    modem = f.get("modem", choice(*named), wired)
    if modem is None:
        raise f.error(f"missing required key 'modem' (whose limits: {', '.join(named)})")
    if wired is not None and modem != wired:
        what = f"backend is {backend}" if backend in DRIVERS else f"emulated modem is {emulated}"
        raise (f.child("modem") or f.node).error(
            f.sub("modem") if "modem" in f else path,
            f"these are the limits of the {DRIVERS[modem].title} but this link's {what}; give the link a "
            f"preset of its own modem")
    base = DRIVERS[modem].limits
    if base is None:
        raise f.error(f"the {DRIVERS[modem].title} has no limits to state (whose limits: {', '.join(named)})")
    modes = dict(base.modes)
    if "modes" in f:
        if not modes:
            raise f.child("modes").error(f.sub("modes"), f"the {DRIVERS[modem].title} has no modes of sending")
        given = Fields(f.child("modes"), f.sub("modes"), tuple(modes))
        for mode in modes:
            modes[mode] = given.get(mode, integer(1, MAX_BYTES), modes[mode])
    send_as = base.send_as
    if "send_as" in f:
        if not modes:
            raise f.child("send_as").error(f.sub("send_as"), f"the {DRIVERS[modem].title} has no modes of sending")
        send_as = f.get("send_as", choice(*(mode for mode in modes if mode in SEND_AS)))
    piece = _only(f, "piece_bytes", base.piece_bytes, integer(3, MAX_BYTES), modem)
    flow = _only(f, "flow_control", base.flow_control, choice("rtscts", "none"), modem)
    limits = replace(base, modes=tuple(modes.items()), send_as=send_as, piece_bytes=piece,
                     flow_control=None if flow == "none" else flow, baud=f.get("baud", integer(50, 4_000_000), base.baud))
    return limits


def _only(f: Fields, key: str, default, check, modem: str):
    """A key only some modems have (the S100's pieces and flow control)."""
    if key not in f:
        return default
    if default is None:
        raise f.child(key).error(f.sub(key), f"the {DRIVERS[modem].title} has no {key}")
    return f.get(key, check)


def describe_limits(link) -> str | None:
    """What ``hilgate check`` prints of a link's limits: its own (stated by its preset or itself), else
    the ones its driver or emulated modem assumes; None for a simulated link that states none."""
    limits = link.limits
    origin = f"preset {link.model}" if link.model else "the link"
    if limits is None:
        modem = link.backend if link.backend in DRIVERS else dict(link.emulate).get("protocol")
        limits = DRIVERS[modem].limits if modem in DRIVERS else None
        origin = f"the {modem} driver's own"
    if limits is None:
        return None
    text = limits.describe()
    if link.backend in DRIVERS:
        options = dict(link.options)
        if limits.modes and link.backend == "evologics":
            im = options.get("im", True)
            text += f"; GLI frames go as {'im' if im else 'burst'} (im: {'true' if im else 'false'})"
        elif link.backend == "micromodem":
            text += f"; GLI frames go as rate{options.get('rate', 1)} (rate: {options.get('rate', 1)})"
        elif link.backend == "m64":
            text += "; GLI frames go as datagrams in 8-byte packets"
        text += f"; the driver queues {dict(link.options).get('queue_frames', 50)} frames"
    else:
        if limits.send_as is not None:
            text += f"; GLI frames go as {limits.send_as} (send_as), larger ones are refused"
        text += f"; transmit FIFO {link.params.fifo_bytes} B"
    return f"limits ({origin}): {text}"
