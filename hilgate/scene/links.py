"""Links: one modem each, simulated (``backend: sim``) or real, keyed by its DCComms id.

A link's keys are its own (vehicle, backend, channels, address), the modem keys a preset may give
(:mod:`.presets`), its MAC (:mod:`.mac`), a real driver's options, or an emulated modem in front of a
simulated link.  Addresses left out are assigned once all links are read (:func:`assign_addresses`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from typing import Any

from ..core.door_table import DOORS
from ..models.errormodel import UNITS, ErrorModel
from ..models.expr import ExprError, compile_expression
from ..models.frame import BROADCAST
from ..models.physical import Acoustic, PhysicalErrorModel
from ..models.modem import ModemParams
from ..models.usbl import UsblParams
from .backends import SIM, backend_names, driver_keys, driver_options, emulated_device
from .hosts import host_name
from .checks import Fields, boolean, choice, describe, integer, join_path, number, text
from .modem_limits import modem_limits
from .mac_spec import mac_spec
from .physics import ERROR_KEYS, acoustic_params, error_kind, physical_environment
from .plugins import Plugin
from .presets import MODEM_KEYS, load_preset, merge
from .ros2 import require_extra
from .specs import LinkSpec, MacSpec
from .unet_spec import unet_door
from .yaml_nodes import Node

__all__ = ["LINK_KEYS", "BACKENDS", "Context", "link_spec", "assign_addresses"]

OWN_KEYS = ("vehicle", "backend", "model", "address", "channel", "tx_channel", "rx_channel", "host",
            "usbl", "gli", "unet")


def link_keys() -> tuple[str, ...]:
    """Every key a link may have: its own, the modem keys, every driver's options (from the backend
    table, read now), ``emulate`` and ``addressing``."""
    return OWN_KEYS + MODEM_KEYS + driver_keys() + ("emulate", "addressing")


LINK_KEYS = link_keys()  # with the drivers of hilgate.drivers.table; the loader asks link_keys() each time
BACKENDS = backend_names()
ADDRESSING = ("auto", "strict")
PACKET_CLASSES = ("raw", "vl1b", "vl2b", "dlf16", "dlf32", "simple:N")
LINK_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,200}")


@dataclass(frozen=True)
class Context:
    """What reading a link needs besides its YAML: where the scene is, the extra preset directories the
    user allowed (``--preset-dir``) and the loaded plugins by name (for ``mac:``)."""

    scene_dir: str
    preset_dirs: tuple[str, ...] = ()
    plugins: dict[str, Plugin] = field(default_factory=dict)


def link_spec(link_id: str, node: Node, path: str, scene: dict[str, Any], ctx: Context) -> LinkSpec:
    if not LINK_ID.fullmatch(link_id):
        raise node.error(path, "a link id must be letters, digits, '_', '.' or '-' (it names POSIX queues)")
    keys = link_keys()
    Fields(node, path, keys)  # unknown keys first, before the preset hides them
    model_node = node.value.get("model")
    merged = node
    if model_node is not None:
        merged = merge(load_preset(model_node, join_path(path, "model"), ctx.scene_dir, ctx.preset_dirs), node)
    f = Fields(merged, path, keys)
    vehicle = f.get("vehicle", text)
    if vehicle not in scene["vehicles"]:
        raise f.child("vehicle").error(f.sub("vehicle"), f"no vehicle {vehicle!r} in the scene")
    backend = f.get("backend", choice(*backend_names()), SIM)
    tx_channel, rx_channel = _channels(f, scene["channels"])
    acoustic_node = f.child("acoustic")
    acoustic = None if acoustic_node is None else acoustic_params(acoustic_node, f.sub("acoustic"))
    params = ModemParams(
        address=f.get("address", _address, -1),
        tx_channel=tx_channel,
        rx_channel=rx_channel,
        bitrate_bps=f.get("bitrate_bps", number(above=0), 1000.0),
        tx_delay_s=f.get("tx_delay_s", number(0), 0.0),
        rx_delay_s=f.get("rx_delay_s", number(0), 0.0),
        tx_jitter_s=f.get("tx_jitter_s", number(0), 0.0),
        rx_jitter_s=f.get("rx_jitter_s", number(0), 0.0),
        fifo_bytes=f.get("fifo_bytes", integer(1), 500_000),
        range_m=f.get("range_m", _range_pair, (0.0, math.inf)),
        error=_link_error(f, acoustic),
        duplex=f.get("duplex", choice("half", "full"), "half"),
        promiscuous=f.get("promiscuous", boolean, False),
        ack_bytes=f.get("ack_bytes", integer(1, 65535), 6),
        ack_turnaround_s=f.get("ack_turnaround_s", number(0), 0.0),
        acoustic=acoustic,
    )
    mac = _mac(f, params, ctx)
    packet = f.get("packet", _packet_class, "vl2b")
    model = None if model_node is None else str(model_node.value)
    options = driver_options(f, backend)
    emulate = _emulate(f, backend)
    protocol = dict(emulate).get("protocol")
    limits = f.get("limits", lambda n, p: modem_limits(n, p, backend, protocol), None)
    addressing = f.get("addressing", choice(*ADDRESSING), "auto")
    usbl = f.get("usbl", _usbl, None)
    if usbl is not None and dict(emulate).get("protocol") != "evologics":
        raise f.child("usbl").error(f.sub("usbl"), "only an emulated EvoLogics modem reports USBL fixes "
                                                   "(give the link emulate: {protocol: evologics, pty: …} or tcp)")
    host = f.get("host", host_name, None)
    address_line = _address_line(f, params, backend, emulate, packet)
    gli = f.get("gli", _gli_endpoints, GLI_DEFAULT)
    unet = f.get("unet", unet_door, ())
    if ("unet" in gli) != bool(unet):
        where = f.child("unet") or f.child("gli") or f.node
        raise where.error(f.sub("unet") if unet else f.sub("gli"),
                          "a UnetStack door needs both gli: [..., unet] and unet: {tcp: PORT}")
    return LinkSpec(link_id, vehicle, backend, model, params, mac, packet, node.file, node.line, options, emulate,
                    addressing, host=host, usbl=usbl, address_line=address_line, gli=gli, limits=limits,
                    unet=unet)


NARROW_MAX = BROADCAST - 1
"""The widest address dccomms and the 8-bit carriers take (255 is the broadcast address)."""

WIDE_MAX = 0xFFFE
"""The widest address of a simulated-only link (16 bits; 0xFFFF is kept back).  255 stays the
broadcast address on every channel, wide or not, so it is never a modem's address."""


def _channels(f: Fields, channels: dict[str, Any]) -> tuple[str, str]:
    """The link's transmit and receive channels: ``channel``, or ``tx_channel`` and ``rx_channel``, or the
    scene's only channel."""
    if "channel" in f:
        if "tx_channel" in f or "rx_channel" in f:
            raise f.error("give either channel or tx_channel + rx_channel, not both")
        tx_channel = rx_channel = f.get("channel", text)
    elif "tx_channel" in f or "rx_channel" in f:
        tx_channel = f.get("tx_channel", text)
        rx_channel = f.get("rx_channel", text)
    elif len(channels) == 1:
        tx_channel = rx_channel = next(iter(channels))
    else:
        raise f.error(f"missing 'channel' (the scene has several: {', '.join(channels)})")
    for key, value in (("channel", tx_channel), ("tx_channel", tx_channel), ("rx_channel", rx_channel)):
        if value not in channels and key in f:
            raise f.child(key).error(f.sub(key), f"no channel {value!r} in the scene; channels: {', '.join(channels)}")
    return tx_channel, rx_channel


def _mac(f: Fields, params: ModemParams, ctx: Context) -> MacSpec:
    """The link's MAC, which checks the modem it runs on (a plugin's check that fails says so)."""
    mac = f.get("mac", lambda n, p: mac_spec(n, p, ctx.plugins), MacSpec("none"))
    try:
        problem = mac.mac_class.check(params, dict(mac.params))
    except Exception as exc:  # a plugin's own check() failed
        problem = f"the MAC's check failed: {type(exc).__name__}: {exc}"
    if problem:
        raise (f.child("mac") or f.node).error(f.sub("mac"), problem)
    return mac


def _emulate(f: Fields, backend: str) -> tuple:
    """The modem a ``backend: sim`` link shows (``emulate:``, with the preset's ``firmware:``); () for none."""
    emulate = ()
    if "emulate" in f:
        if backend != SIM:
            raise f.child("emulate").error(f.sub("emulate"), "only a backend: sim link can emulate a modem")
        emulate = f.get("emulate", emulated_device)
        firmware = f.get("firmware", _firmware, ())
        if firmware:
            emulate += (("firmware", firmware),)
    elif "firmware" in f:
        f.get("firmware", _firmware)  # checked (a preset gives it to every link), used only when emulating
    return emulate


def _address_line(f: Fields, params: ModemParams, backend: str, emulate: tuple, packet: Any) -> int:
    """The line of an address wider than 8 bits (0: it is not), refused where it cannot travel."""
    address_line = 0
    if params.address > NARROW_MAX:
        child = f.child("address")
        address_line = child.line
        problem = _wide_problem(backend, emulate, packet)
        if problem:
            raise child.error(f.sub("address"), f"{params.address} is wider than 8 bits (0..{NARROW_MAX}): {problem}")
    return address_line


def _address(node: Node, path: str) -> int:
    value = integer(0, WIDE_MAX)(node, path)
    if value == BROADCAST:
        raise node.error(path, f"{BROADCAST} is the broadcast address, not a modem's")
    return value


def _wide_problem(backend: str, emulate: tuple, packet: str) -> str:
    """Why a link cannot have an address above 254, or "" if it can: only a simulated link that no
    8-bit carrier touches (a real modem, an emulated one, a packet class with a u8 address on air)."""
    from ..core.packets import packet_class

    if backend != SIM:
        return f"a real modem (backend: {backend}) has an 8-bit address"
    if emulate:
        return "an emulated modem speaks 8-bit addresses (AT protocol)"
    if packet_class(packet).addresses_on_air:
        return f"packet class {packet} carries a one-byte address on air"
    return ""


def _no_free_address(link: LinkSpec) -> str:
    """Automatic addresses stop at 254; say how to go on, as far as this link allows."""
    text = ("no free address left (1..254 are taken); give links an address: of their own (it need only differ "
            "among the links of one channel)")
    problem = _wide_problem(link.backend, link.emulate, link.packet)
    if problem:
        return f"{text}; this link cannot take one above {NARROW_MAX}: {problem}"
    return (f"{text}, up to {WIDE_MAX} under hilgate sim (this link's packet class keeps addresses off the air; "
            f"hilgate run takes 0..{NARROW_MAX} only)")


def require_narrow_addresses(links: Any) -> None:
    """``hilgate run`` attaches dccomms applications (POSIX queues) and the socket GLI, whose ``u8 dst``
    carries 8 bits, to every link: a wide address is refused there, naming its file, line and key."""
    from .yaml_nodes import SceneError

    for link in links:
        if link.params.address > NARROW_MAX:
            raise SceneError(link.file, link.address_line or link.line, f"links.{link.id}.address",
                             f"{link.params.address} is wider than 8 bits (0..{NARROW_MAX}): hilgate run attaches "
                             f"dccomms queues and the socket GLI (8-bit addresses) to every link; wide addresses "
                             f"are for hilgate sim")


GLI_ORDER = ("mq", "socket", "ros2", "unet")  # (how a link's gli: is listed in its view, as always)
GLI_ENDPOINTS = tuple(sorted((name for name, door in DOORS.items() if door.gli),
                             key=lambda name: (GLI_ORDER.index(name) if name in GLI_ORDER else len(GLI_ORDER), name)))
"""The ``gli:`` values: the rows of the door table (:mod:`hilgate.core.door_table`) that a link asks for."""
GLI_DEFAULT = ("mq", "socket")


def _gli_endpoints(node: Node, path: str) -> tuple[str, ...]:
    """``gli: [mq, socket]`` (the default), ``[socket]``, ``[mq]`` or ``[]``, and ``ros2`` and ``unet`` besides:
    which GLI endpoints the link opens (``unet``: a UnetStack node on the port its ``unet:`` key gives).  Every ``mq`` link costs two POSIX queues of a per-user and a system-wide
    budget; a link only socket applications (or only an emulated modem) use needs none.  ``ros2`` opens
    the link's ROS 2 topics (:mod:`hilgate.ros2.door`), and needs the ros2 extra."""
    items = [node] if isinstance(node.value, str) else node.value if node.is_list else None
    if items is None:
        raise node.error(path, f"must be a list of {' and '.join(GLI_ENDPOINTS)} (e.g. [socket]), not {describe(node)}")
    chosen = []
    for i, item in enumerate(items):
        item_path = path if item is node else join_path(path, i)
        value = choice(*GLI_ENDPOINTS)(item, item_path)
        if value == "ros2":
            require_extra(item, item_path)
        if value in chosen:
            raise item.error(item_path, f"{value} is given twice")
        chosen.append(value)
    return tuple(name for name in GLI_ENDPOINTS if name in chosen)


FIRMWARE_KEYS = ("version", "phy", "mac", "manufacturer", "mode")


def _firmware(node: Node, path: str) -> tuple[tuple[str, str], ...]:
    """``firmware: {version, phy, mac, manufacturer, mode}``: what an emulated modem says it is (ATI0,
    ATI1, ATI7, AT?MODE), as texts (a version written 1.10 unquoted would read as 1.1)."""
    f = Fields(node, path, FIRMWARE_KEYS)
    values = []
    for key in FIRMWARE_KEYS:
        child = f.child(key)
        if child is None:
            continue
        if not isinstance(child.value, str):
            raise child.error(f.sub(key), f"must be a text in quotes (e.g. \"1.9\"), not {describe(child)}")
        values.append((key, text(child, f.sub(key))))
    return tuple(values)


def assign_addresses(links: dict[str, LinkSpec], nodes: dict[str, Node]) -> dict[str, LinkSpec]:
    """Links without ``address`` get the smallest free one; two simulated links that listen on one
    channel must not share an address."""
    used = {link.params.address for link in links.values() if link.params.address >= 0}
    next_free = 1
    result: dict[str, LinkSpec] = {}
    owners: dict[tuple[str, int], str] = {}
    for link_id, link in links.items():
        if link.params.address < 0:
            while next_free in used:
                next_free += 1
            if next_free >= BROADCAST:
                raise nodes[link_id].error(f"links.{link_id}", _no_free_address(link))
            used.add(next_free)
            link = _replace_params(link, address=next_free)
        key = (link.params.rx_channel, link.params.address)
        if link.backend != SIM:
            result[link_id] = link  # a real modem's address is the modem's own, not on the medium
            continue
        if key in owners:
            raise nodes[link_id].error(
                f"links.{link_id}.address",
                f"address {link.params.address} is already used by link {owners[key]!r} on channel {key[0]!r}",
            )
        owners[key] = link_id
        result[link_id] = link
    return result


def _replace_params(link: LinkSpec, **changes: Any) -> LinkSpec:
    return replace(link, params=replace(link.params, **changes))


# -- modem keys ------------------------------------------------------------------------------------


def _range_pair(node: Node, path: str) -> tuple[float, float]:
    if not node.is_list or len(node.value) != 2:
        raise node.error(path, f"must be [min, max] in metres, not {describe(node)}")
    low = number(0)(node.value[0], join_path(path, 0))
    high = number(0, allow_inf=True)(node.value[1], join_path(path, 1))
    if high < low:
        raise node.error(path, f"max {high:g} is below min {low:g}")
    return (low, high)


def _usbl(node: Node, path: str) -> UsblParams | None:
    """``usbl: true`` or ``{orientation_deg: [roll, pitch, yaw], bearing_sigma_deg, range_sigma_m}``."""
    if isinstance(node.value, bool):
        return UsblParams() if node.value else None
    if not node.is_map:
        raise node.error(path, f"must be true, false or a mapping of orientation_deg, bearing_sigma_deg, "
                               f"range_sigma_m, not {describe(node)}")
    f = Fields(node, path, ("orientation_deg", "bearing_sigma_deg", "range_sigma_m"))
    orientation = (0.0, 0.0, 0.0)
    child = f.child("orientation_deg")
    if child is not None:
        if not child.is_list or len(child.value) != 3:
            raise child.error(f.sub("orientation_deg"), f"must be [roll, pitch, yaw] in degrees, not {describe(child)}")
        orientation = tuple(math.radians(number(-360, 360)(item, join_path(f.sub("orientation_deg"), i)))
                            for i, item in enumerate(child.value))
    return UsblParams(orientation, math.radians(f.get("bearing_sigma_deg", number(0, 180), 0.0)),
                      f.get("range_sigma_m", number(0), 0.0))


def _link_error(link: Fields, acoustic: Acoustic | None) -> ErrorModel | PhysicalErrorModel:
    """The link's ``error:``: an expression of distance (kind ``expr``, the default), or the physical
    model (kind ``physical``), which also takes the link's ``acoustic:`` front end and bit rate.  The
    front end is the link's whatever its error (``ModemParams.acoustic``): as a sender it is what other
    links hear (``models/path.py``)."""
    node = link.child("error")
    if node is None:
        return ErrorModel("packet", "0")
    path = link.sub("error")
    if error_kind(node, path) == "expr":
        return _error_model(node, path)
    env = physical_environment(node, path)
    if acoustic is None:
        raise node.error(path, "kind: physical needs the link's acoustic: {band_khz, source_level_db, …} "
                               "(a preset such as evologics-s2cr-18-34 gives it)")
    bitrate = link.get("bitrate_bps", number(above=0), 1000.0)
    try:
        return PhysicalErrorModel(env, acoustic, bitrate)
    except ValueError as exc:
        raise node.error(path, str(exc)) from None


def _error_model(node: Node, path: str) -> ErrorModel:
    f = Fields(node, path, ERROR_KEYS)
    for key in ERROR_KEYS:
        if key not in ("kind", "unit", "expr") and key in f:
            raise f.child(key).error(f.sub(key), "only for kind: physical")
    unit = f.get("unit", choice(*UNITS), "packet")
    expr_node = f.child("expr")
    if expr_node is None:
        raise f.error("missing required key 'expr' (e.g. \"6e-13 * d^13.7\")")
    try:
        expression = compile_expression(expr_node.value)
    except ExprError as exc:
        raise expr_node.error(f.sub("expr"), f"bad error-rate expression: {exc}") from None
    return ErrorModel(unit, expression)


def _packet_class(node: Node, path: str) -> str:
    value = node.value
    if isinstance(value, str):
        if value in ("raw", "vl1b", "vl2b", "dlf16", "dlf32"):
            return value
        match = re.fullmatch(r"simple:([0-9]{1,5})", value)
        if match and 4 <= int(match.group(1)) <= 8000:
            return value
    raise node.error(path, f"must be one of {', '.join(PACKET_CLASSES)} (N, the whole packet, from 4 to 8000 "
                           f"bytes), not {describe(node)}")
