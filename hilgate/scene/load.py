"""Scene files: load, merge presets, apply ``--set`` overrides, validate whole, return typed specs.

A scene is validated completely before anything is built from it, so a bad scene never half-starts
(and a bad reload never disturbs the running one).  Every error is a :class:`SceneError` printed as
``FILE:LINE: key.path: what is wrong``.  The format is DESIGN.md's "Scene file" section.
"""

from __future__ import annotations

import importlib.resources
import logging
import math
import os
import re
import stat
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from .checks import (
    Fields, boolean, choice, describe, integer, items, join_path, mapping, number, quote, text, vector,
)
from .yaml_nodes import MAX_DEPTH, MAX_FILE_BYTES, Node, SceneError, load_file, load_text, parse_scalar, read_limited, size_text
from .plugins import Plugin, PluginError, class_from_origin, classes_of, load_plugin, origin_of
from ..models.errormodel import UNITS, ErrorModel
from ..models.expr import ExprError, compile_expression
from ..models.flows import FlowSpec
from ..models.frame import BROADCAST
from ..models.mac import Mac, Param
from ..models.macs import REGISTRY as MAC_REGISTRY
from ..models.medium import Channel
from ..models.modem import ModemParams

__all__ = [
    "SceneError", "Scene", "VehicleSpec", "PoseSpec", "LinkSpec", "MacSpec", "load_scene", "load_scene_text",
    "preset_names", "POSE_KINDS", "BACKENDS",
]

log = logging.getLogger(__name__)

TOP_KEYS = ("name", "seed", "duration_s", "plugins", "channels", "vehicles", "links", "flows", "trace", "cameras")
CHANNEL_KEYS = ("speed_mps", "min_delay_s")
VEHICLE_KEYS = ("pose", "stale_after_s", "stale", "extrapolate_s", "initial", "feedback")
LIVE_KINDS = ("mavlink", "aruco")
CAMERA_KEYS = ("source", "calibration", "dictionary", "marker_length_m", "fixed", "onboard", "map", "fps")
MODEM_KEYS = (
    "bitrate_bps", "tx_delay_s", "rx_delay_s", "tx_jitter_s", "rx_jitter_s", "fifo_bytes", "range_m",
    "error", "mac", "packet", "duplex", "promiscuous",
)
DRIVER_KEYS = {
    "evologics": ("port", "baud", "im", "ack", "source_level", "gain", "extended", "im_retries", "command_timeout_s",
                  "delivery_timeout_s", "queue_frames", "eol"),
    "s100": ("port", "baud", "rtscts", "queue_frames"),
}
ALL_DRIVER_KEYS = tuple(dict.fromkeys(k for keys in DRIVER_KEYS.values() for k in keys))
LINK_KEYS = ("vehicle", "backend", "model", "address", "channel", "tx_channel", "rx_channel") + MODEM_KEYS + \
    ALL_DRIVER_KEYS + ("emulate", "addressing")
ADDRESSING = ("auto", "strict")
FLOW_KEYS = ("from", "to", "size_bytes", "interval_s", "rate_hz", "poisson", "start_s", "stop_s")
BACKENDS = ("sim", "evologics", "s100")
PACKET_CLASSES = ("raw", "vl1b", "vl2b", "dlf16", "dlf32", "simple:N")
LINK_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,200}")
PRESET_SUFFIXES = (".yaml", ".yml")
MAX_PRESET_BYTES = 64 * 1024


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

    def link_of_address(self, channel: str, address: int) -> LinkSpec | None:
        for link in self.links.values():
            if link.params.rx_channel == channel and link.params.address == address:
                return link
        return None


# -- what a scene may reference: paths, presets, plugins ----------------------------------------


@dataclass(frozen=True)
class _Context:
    """What validation needs besides the YAML: where the scene is, the extra preset directories the
    user allowed (``--preset-dir``) and the loaded plugins by name."""

    scene_dir: str
    preset_dirs: tuple[str, ...] = ()
    plugins: dict[str, Plugin] = field(default_factory=dict)


def base_dir(node: Node) -> str:
    """The directory a relative path written in ``node`` is taken from: that of the file it was
    written in (a scene travels with the files it names, and under systemd the working directory is
    /var/lib/hilgate), or the working directory for a value given on the command line (``--set``)."""
    if not node.file or node.file.startswith(("<", "-")):  # "<scene>" text, "--set", "--plugin"
        return os.getcwd()
    return os.path.dirname(os.path.abspath(node.file))


def path_value(node: Node, path: str) -> str:
    """Checker: a file path, made absolute relative to the file that names it (see :func:`base_dir`)."""
    value = text(node, path)
    if "\0" in value:
        raise node.error(path, "a path cannot contain a NUL character")
    return os.path.normpath(os.path.join(base_dir(node), value))


def _inside(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def preset_names() -> list[str]:
    folder = importlib.resources.files("hilgate.models")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def _load_preset(name_node: Node, path: str, ctx: _Context) -> Node:
    """A packaged preset by name, or a preset file the scene may read (see :func:`_preset_file`)."""
    name = text(name_node, path)
    if name in preset_names():
        resource = importlib.resources.files("hilgate.models") / f"{name}.yaml"
        node = load_text(resource.read_text(encoding="utf-8"), f"models/{name}.yaml")
    elif name.endswith(PRESET_SUFFIXES) or "/" in name or os.sep in name:
        file, real, info = _preset_file(name_node, path, name, ctx)
        try:
            node = load_text(read_limited(real, MAX_PRESET_BYTES, "the preset", expect=info), file, MAX_PRESET_BYTES)
        except SceneError as exc:
            if exc.line or exc.file != real:
                raise
            raise name_node.error(path, exc.message) from None
    else:
        raise name_node.error(path, f"unknown modem model {quote(name)}; presets: {', '.join(preset_names())} "
                                    "(or a .yaml file of your own in the scene's directory)")
    if node is None or not node.is_map:
        raise SceneError(node.file if node else name, node.line if node else 0, "", "a modem preset must be a mapping of link keys")
    Fields(node, "", MODEM_KEYS)
    return node


def _preset_file(node: Node, path: str, name: str, ctx: _Context) -> tuple[str, str, os.stat_result]:
    """Where a preset file is, checked before it is opened: a ``.yaml``/``.yml`` regular file of at most
    64 KB whose real path (symbolic links resolved) lies under the scene's directory or a
    ``--preset-dir``.  Anything else (``/etc/shadow``, ``/dev/zero``, a FIFO) is refused unread, so no
    error can show a line of it.  Returns (the path as named, its real path, its stat)."""
    if "\0" in name:
        raise node.error(path, "a path cannot contain a NUL character")
    if not name.endswith(PRESET_SUFFIXES):
        raise node.error(path, "a preset file must end in .yaml or .yml")
    file = os.path.normpath(os.path.join(base_dir(node), name))
    real = os.path.realpath(file)
    roots = [os.path.realpath(folder) for folder in (ctx.scene_dir, *ctx.preset_dirs)]
    if not any(_inside(real, root) for root in roots):
        raise node.error(path, f"preset {quote(name)} is outside the scene's directory {ctx.scene_dir}"
                               + (" and the --preset-dir directories" if ctx.preset_dirs else "")
                               + " (add its directory with --preset-dir)")
    try:
        info = os.stat(real)
    except OSError as exc:
        raise node.error(path, f"cannot read preset {quote(name)}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        raise node.error(path, f"preset {quote(name)} is not a regular file")
    if info.st_size > MAX_PRESET_BYTES:
        raise node.error(path, f"preset {quote(name)} is larger than {size_text(MAX_PRESET_BYTES)}")
    return file, real, info


def _load_plugins(node: Node | None, extra: Sequence[str]) -> dict[str, Plugin]:
    """The scene's ``plugins:`` (relative to the scene) and ``--plugin`` ones (relative to the working
    directory), loaded: the only user code a scene runs."""
    plugins: dict[str, Plugin] = {}
    entries: list[tuple[Node, str]] = []
    if node is not None and node.value is not None:
        entries = [(item, join_path("plugins", i)) for i, item in enumerate(items(node, "plugins"))]
    entries += [(Node(entry, "--plugin", 0), "") for entry in extra]
    for item, path in entries:
        entry = text(item, path) if path else str(item.value)
        try:
            plugin = load_plugin(entry, base_dir(item))
        except PluginError as exc:
            raise item.error(path, f"cannot load plugin {quote(entry)}: {exc}") from None
        other = plugins.get(plugin.name)
        if other is not None and other.source != plugin.source:
            raise item.error(path, f"two plugins are named {plugin.name!r}: {other.source} and {plugin.source}")
        plugins[plugin.name] = plugin
    return plugins


def _merge(base: Node, override: Node) -> Node:
    """Key-by-key override, one level into nested mappings (``error``, ``mac``)."""
    if not (base.is_map and override.is_map):
        return override
    merged = dict(base.value)
    for key, value in override.items():
        merged[key] = _merge(merged[key], value) if key in merged else value
    return Node(merged, override.file, override.line)


# -- --set overrides ------------------------------------------------------------------------------


def apply_override(root: Node, assignment: str) -> None:
    """``links.*.mac.protocol=s-fama``: set a value, ``*`` matching every key at that level; a value of
    ``null`` removes the key (``links.*.mac.backoff_s=null`` when switching to a MAC without it)."""
    if "=" not in assignment:
        raise SceneError("--set", 0, assignment, "expected KEY.PATH=VALUE")
    path, raw = assignment.split("=", 1)
    parts = [p for p in path.strip().split(".")]
    if not all(parts):
        raise SceneError("--set", 0, path, "empty key in the path")
    if len(parts) > MAX_DEPTH:
        raise SceneError("--set", 0, path, f"a key path deeper than {MAX_DEPTH} levels")
    value = parse_scalar(raw)

    def to_node(v: Any) -> Node:
        if isinstance(v, dict):
            return Node({str(k): to_node(x) for k, x in v.items()}, "--set", 0)
        if isinstance(v, list):
            return Node([to_node(x) for x in v], "--set", 0)
        return Node(v, "--set", 0)

    def walk(node: Node, index: int, where: str) -> int:
        key = parts[index]
        if not node.is_map:
            raise SceneError("--set", 0, where, f"is {describe(node)}, cannot set {key!r} in it")
        targets = list(node.value) if key == "*" else [key]
        done = 0
        for name in targets:
            if index == len(parts) - 1:
                if value is None:
                    done += node.value.pop(name, None) is not None or key == "*"
                else:
                    node.value[name] = to_node(value)
                    done += 1
            else:
                child = node.value.get(name)
                if child is None:
                    child = node.value[name] = Node({}, "--set", 0)
                done += walk(child, index + 1, join_path(where, name))
        return done

    if walk(root, 0, "") == 0:
        raise SceneError("--set", 0, path, "matched nothing")


# -- checkers for scene sections ------------------------------------------------------------------


def _range_pair(node: Node, path: str) -> tuple[float, float]:
    if not node.is_list or len(node.value) != 2:
        raise node.error(path, f"must be [min, max] in metres, not {describe(node)}")
    low = number(0)(node.value[0], join_path(path, 0))
    high = number(0, allow_inf=True)(node.value[1], join_path(path, 1))
    if high < low:
        raise node.error(path, f"max {high:g} is below min {low:g}")
    return (low, high)


def _error_model(node: Node, path: str) -> ErrorModel:
    f = Fields(node, path, ("unit", "expr"))
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


def _plugin_macs(plugins: dict[str, Plugin]) -> dict[str, list[tuple[str, type[Mac]]]]:
    """MAC classes the plugins define, by their own ``name`` attribute → [(``plugin:Class``, class)]."""
    found: dict[str, list[tuple[str, type[Mac]]]] = {}
    for plugin in plugins.values():
        for attr, cls in classes_of(plugin, Mac).items():
            name = cls.__dict__.get("name")
            if isinstance(name, str) and name:
                found.setdefault(name, []).append((f"{plugin.name}:{attr}", cls))
    return found


def _mac_class(protocol: str, node: Node, path: str, plugins: dict[str, Plugin]) -> type[Mac]:
    """The class a ``protocol`` names: built in, ``plugin:Class`` of a listed plugin, or the ``name``
    of a MAC a listed plugin defines.  Never imports anything: plugins are loaded already."""
    if protocol in MAC_REGISTRY:
        return MAC_REGISTRY[protocol]
    if ":" in protocol:
        plugin_name, _, class_name = protocol.partition(":")
        plugin = plugins.get(plugin_name)
        if plugin is None:
            raise node.error(path, f"MAC {quote(protocol)}: {quote(plugin_name)} is not a listed plugin (list its .py "
                                   "file or module under plugins:, or give --plugin)")
        cls = getattr(plugin.module, class_name, None) if class_name.isidentifier() else None
        if cls is None:
            raise node.error(path, f"plugin {plugin_name!r} has no {quote(class_name)}")
        if not (isinstance(cls, type) and issubclass(cls, Mac)):
            raise node.error(path, f"{quote(protocol)} is not a MAC (a subclass of hilgate.models.mac.Mac)")
        return cls
    provided = _plugin_macs(plugins)
    if len(provided.get(protocol, ())) == 1:
        return provided[protocol][0][1]
    if protocol in provided:
        raise node.error(path, f"MAC {protocol!r} is defined by several plugins ("
                               f"{', '.join(ref for ref, _ in provided[protocol])}); name one as plugin:Class")
    offered = ", ".join(f"{name} ({refs[0][0]})" for name, refs in provided.items())
    raise node.error(path, f"unknown MAC protocol {quote(protocol)}; built in: {', '.join(MAC_REGISTRY)}"
                           + (f"; from plugins: {offered}" if offered else "")
                           + " (a MAC of your own comes from a .py file or module listed under plugins:)")


def _param_value(param: Param, node: Node, path: str) -> Any:
    if param.kind == "number":
        return number(param.minimum, param.maximum)(node, path)
    if param.kind == "integer":
        low = None if param.minimum is None else int(param.minimum)
        high = None if param.maximum is None else int(param.maximum)
        return integer(low, high)(node, path)
    if param.kind == "boolean":
        return boolean(node, path)
    if param.kind == "pair":
        pair = vector(2)(node, path)
        if param.minimum is not None and min(pair) < param.minimum:
            raise node.error(path, f"values must be at least {param.minimum:g}")
        if pair[1] < pair[0]:
            raise node.error(path, f"max {pair[1]:g} is below min {pair[0]:g}")
        return pair
    raise node.error(path, f"internal: unknown parameter kind {param.kind!r}")


def _mac_spec(node: Node, path: str, plugins: dict[str, Plugin]) -> MacSpec:
    if isinstance(node.value, str):  # shorthand: mac: cs-aloha
        node = Node({"protocol": Node(node.value, node.file, node.line)}, node.file, node.line)
    values = mapping(node, path)
    proto_node = values.get("protocol")
    if proto_node is None:
        raise node.error(path, "missing required key 'protocol'")
    protocol = text(proto_node, join_path(path, "protocol"))
    cls = _mac_class(protocol, proto_node, join_path(path, "protocol"), plugins)
    f = Fields(node, path, ("protocol",) + tuple(cls.PARAMETERS))
    params = []
    for key, param in cls.PARAMETERS.items():
        value = f.get(key, lambda n, p, param=param: _param_value(param, n, p), param.default)
        if value is not None:
            params.append((key, value))
    return MacSpec(protocol, tuple(params), None if protocol in MAC_REGISTRY else cls)


# -- pose sources ---------------------------------------------------------------------------------


def _static_pose(node: Node, path: str) -> Any:
    return vector()(node, path)


def _leg(node: Node, path: str) -> dict[str, Any]:
    f = Fields(node, path, ("hold_s", "to", "speed_mps", "duration_s"))
    if "hold_s" in f:
        if any(k in f for k in ("to", "speed_mps", "duration_s")):
            raise f.error("a leg is either {hold_s} or {to, speed_mps} or {to, duration_s}")
        return {"hold_s": f.get("hold_s", number(0))}
    to = f.get("to", vector())
    if ("speed_mps" in f) == ("duration_s" in f):
        raise f.error("a leg with 'to' needs exactly one of speed_mps or duration_s")
    if "speed_mps" in f:
        return {"to": to, "speed_mps": f.get("speed_mps", number(above=0))}
    return {"to": to, "duration_s": f.get("duration_s", number(0))}


def _path_pose(node: Node, path: str) -> Any:
    f = Fields(node, path, ("start", "legs", "loop"))
    start = f.get("start", vector())
    legs_node = f.child("legs")
    legs = [] if legs_node is None else [_leg(n, join_path(f.sub("legs"), i)) for i, n in enumerate(items(legs_node, f.sub("legs")))]
    loop = f.get("loop", boolean, False)
    if loop:
        from ..models.trajectories import path_segments

        segments = path_segments(start, legs)
        if segments[-1].t1 <= 0:
            raise f.error("a looping path needs legs that take time")
        end = segments[-1].p1
        if math.dist(end, start) > 1e-6:
            raise f.error(f"a looping path must end where it starts {list(start)}, it ends at {list(end)}")
    return (start, tuple(tuple(sorted(leg.items())) for leg in legs), loop)


def _waypoints_pose(node: Node, path: str) -> Any:
    rows = []
    previous = -math.inf
    for i, row in enumerate(items(node, path)):
        values = vector(4)(row, join_path(path, i))
        if values[0] <= previous:
            raise row.error(join_path(path, i), f"times must increase: {values[0]:g} after {previous:g}")
        previous = values[0]
        rows.append(values)
    if not rows:
        raise node.error(path, "needs at least one [t, x, y, z] row")
    return tuple(rows)


def _controlled_pose(node: Node, path: str) -> Any:
    f = Fields(node, path, ("start", "max_speed_mps"))
    return (f.get("start", vector()), f.get("max_speed_mps", number(above=0)))


def _mavlink_pose(node: Node, path: str) -> Any:
    f = Fields(node, path, ("url", "system_id", "origin", "message_rates", "heartbeat"))
    url = f.get("url", text)
    system_id = f.get("system_id", integer(1, 255), None)
    origin = f.get("origin", vector(3), None)  # latitude, longitude (degrees), altitude (m)
    rates: tuple = ()
    rates_node = f.child("message_rates")
    if rates_node is not None:
        rates = tuple((name, number(above=0, maximum=1000)(value, join_path(f.sub("message_rates"), name)))
                      for name, value in mapping(rates_node, f.sub("message_rates")).items())
    # hilgate sends a vehicle nothing the scene did not ask for, and never as its ground station
    # (drivers/mavlink_identity.py says why): heartbeat: false (default) | true | {system_id, component_id, rate_hz}
    from ..drivers import mavlink_identity as ident

    hb_node, hb_path = f.child("heartbeat"), f.sub("heartbeat")
    heartbeat = None
    if hb_node is not None and not hb_node.is_map and not isinstance(hb_node.value, bool):
        raise hb_node.error(hb_path, "must be true, false or {system_id: N, component_id: M, rate_hz: R}")
    if hb_node is not None and (hb_node.is_map or hb_node.value):
        own, component, rate = system_id, ident.DEFAULT_COMPONENT_ID, ident.DEFAULT_HEARTBEAT_HZ  # as a companion's
        where = {"system_id": (f.child("system_id"), f.sub("system_id")), "component_id": (hb_node, hb_path)}
        if hb_node.is_map:
            hf = Fields(hb_node, hb_path, ("system_id", "component_id", "rate_hz"))
            own = hf.get("system_id", integer(1, 255), own)
            component = hf.get("component_id", integer(1, 255), component)
            rate = hf.get("rate_hz", number(above=0, maximum=10), rate)
            where.update({key: (hf.child(key), hf.sub(key)) for key in ("system_id", "component_id") if key in hf})
        if own is None:
            raise hb_node.error(hb_path, "needs a system id to send as: give the vehicle's system_id (hilgate then "
                                "sends as its companion computer does) or heartbeat: {system_id: N}")
        for key, problem in (("system_id", ident.system_problem(own)),
                             ("component_id", ident.component_problem(component))):
            if problem is not None:
                raise where[key][0].error(where[key][1], problem)
        heartbeat = (("system_id", own), ("component_id", component), ("rate_hz", rate))
    return (("url", url), ("system_id", system_id), ("origin", origin), ("message_rates", rates),
            ("heartbeat", heartbeat))


def _aruco_pose(node: Node, path: str) -> Any:
    f = Fields(node, path, ("camera", "marker", "offset"))
    camera = f.get("camera", text)
    marker = f.get("marker", integer(0, 100_000), None)
    offset = f.get("offset", vector(), (0.0, 0.0, 0.0))
    return (("camera", camera), ("marker", marker), ("offset", offset))


POSE_KINDS: dict[str, Callable[[Node, str], Any]] = {
    "static": _static_pose,
    "path": _path_pose,
    "waypoints": _waypoints_pose,
    "controlled": _controlled_pose,
    "mavlink": _mavlink_pose,
    "aruco": _aruco_pose,
}


def _vehicle(name: str, node: Node, path: str) -> VehicleSpec:
    f = Fields(node, path, VEHICLE_KEYS)
    pose_node = f.child("pose")
    if pose_node is None:
        raise f.error("missing required key 'pose'")
    pose_path = f.sub("pose")
    kinds = dict(mapping(pose_node, pose_path))
    merge_node = kinds.pop("merge", None)
    for kind, params_node in kinds.items():
        if kind not in POSE_KINDS:
            raise params_node.error(join_path(pose_path, kind), unknown_pose(kind))
    if not kinds:
        raise pose_node.error(pose_path, f"give a pose source: {', '.join(POSE_KINDS)}")
    live = [k for k in kinds if k in LIVE_KINDS]
    if len(kinds) > 1 and len(live) != len(kinds):
        raise pose_node.error(pose_path, "only live sources (mavlink, aruco) can be combined, with merge")
    if len(kinds) > 1 and merge_node is None:
        raise pose_node.error(pose_path, "several sources need 'merge' (e.g. {x: aruco, y: aruco, z: mavlink})")
    merge: tuple = ()
    if merge_node is not None:
        mf = Fields(merge_node, join_path(pose_path, "merge"), ("x", "y", "z"))
        merge = tuple((axis, mf.get(axis, choice(*live))) for axis in ("x", "y", "z") if axis in mf)
    if live:
        sources = tuple((kind, POSE_KINDS[kind](kinds[kind], join_path(pose_path, kind))) for kind in kinds)
        pose = PoseSpec("live", sources, merge)
    else:
        (kind, params_node), = kinds.items()
        pose = PoseSpec(kind, POSE_KINDS[kind](params_node, join_path(pose_path, kind)))
    if not live:
        for key in ("stale_after_s", "stale", "extrapolate_s", "initial"):
            if key in f:
                raise f.child(key).error(f.sub(key), "only for vehicles with a live pose (mavlink, aruco)")
    feedback: tuple = ()
    if "feedback" in f:
        ff = Fields(f.child("feedback"), f.sub("feedback"), ("url", "message", "rate_hz", "origin", "system_id"))
        message = ff.get("message", choice("vision_position_estimate", "gps_input"), "vision_position_estimate")
        origin = ff.get("origin", vector(3), None)
        if message == "gps_input" and origin is None:
            raise ff.error("gps_input needs origin: [latitude, longitude, altitude]")
        feedback = (("url", ff.get("url", text)), ("message", message), ("rate_hz", ff.get("rate_hz", number(above=0,
                    maximum=100), 4.0)), ("origin", origin), ("system_id", ff.get("system_id", integer(1, 255), 1)))
    return VehicleSpec(
        name, pose, node.line,
        stale_after_s=f.get("stale_after_s", number(above=0), 2.0),
        stale=f.get("stale", choice("hold", "drop"), "hold"),
        extrapolate_s=f.get("extrapolate_s", number(0), 0.0),
        initial=f.get("initial", vector(), None),
        feedback=feedback,
    )


def _placement(node: Node, path: str) -> tuple:
    f = Fields(node, path, ("position", "rpy_deg"))
    return (f.get("position", vector()), f.get("rpy_deg", vector(), (0.0, 0.0, 0.0)))


def _camera(name: str, node: Node, path: str, vehicles: dict[str, VehicleSpec]) -> CameraSpec:
    f = Fields(node, path, CAMERA_KEYS)
    source_node = f.child("source")
    if source_node is None:
        raise f.error("missing required key 'source' (a device index, a video file or a stream URL)")
    source = _camera_source(source_node, f.sub("source"))
    from ..drivers.aruco import DICTIONARIES

    dictionary = f.get("dictionary", choice(*DICTIONARIES), "DICT_4X4_50")
    if ("fixed" in f) == ("onboard" in f):
        raise f.error("give exactly one of fixed (the camera's place in the tank) or onboard (on a vehicle)")
    fixed = onboard = None
    markers: tuple = ()
    if "fixed" in f:
        fixed = f.get("fixed", _placement)
        if "map" in f:
            raise f.child("map").error(f.sub("map"), "a map of markers is for an onboard camera")
    else:
        of = Fields(f.child("onboard"), f.sub("onboard"), ("vehicle", "position", "rpy_deg"))
        vehicle = of.get("vehicle", text)
        if vehicle not in vehicles:
            raise of.child("vehicle").error(of.sub("vehicle"), f"no vehicle {vehicle!r}")
        onboard = (vehicle, of.get("position", vector(), (0.0, 0.0, 0.0)), of.get("rpy_deg", vector(), (0.0, 0.0, 0.0)))
        map_node = f.child("map")
        if map_node is None:
            raise f.error("an onboard camera needs a map of markers fixed in the tank")
        entries = []
        for marker_id, marker_node in mapping(map_node, f.sub("map")).items():
            where = join_path(f.sub("map"), marker_id)
            if not re.fullmatch(r"[0-9]{1,9}", marker_id):
                raise marker_node.error(where, "map keys are marker ids (whole numbers)")
            entries.append((int(marker_id), *_placement(marker_node, where)))
        markers = tuple(entries)
    return CameraSpec(name, source, f.get("calibration", _calibration), dictionary, f.get("marker_length_m", number(above=0)),
                      fixed, onboard, markers, f.get("fps", number(above=0), None))



def _camera_source(node: Node, path: str) -> int | str:
    """A device index, a stream URL or a GStreamer pipeline as written; a video file relative to the scene."""
    source = node.value
    if isinstance(source, bool) or not isinstance(source, (int, str)) or source == "":
        raise node.error(path, f"must be a device index or a text, not {describe(node)}")
    if isinstance(source, str) and "://" not in source and not re.search(r"[\s!]", source) and not source.isdigit():
        return path_value(node, path)
    return source


def _calibration(node: Node, path: str) -> str:
    """The camera's calibration file, relative to the scene, read now by the camera driver's own
    reader so that a missing or broken one fails ``hilgate check`` (not the daemon, later)."""
    file = path_value(node, path)
    if not os.path.lexists(file):
        raise node.error(path, f"calibration file {file} does not exist")
    try:
        read_limited(file, MAX_FILE_BYTES, "the calibration file")  # a regular, readable, small file
    except SceneError as exc:
        raise node.error(path, f"{file}: {exc.message}") from None
    from ..drivers.aruco import CameraError, load_calibration

    try:
        load_calibration(file)
    except CameraError as exc:
        raise node.error(path, str(exc)) from None
    return file


def unknown_pose(kind: str) -> str:
    from .checks import unknown_key_message

    return unknown_key_message(kind, list(POSE_KINDS)).replace("unknown key", "unknown pose source")


# -- links ----------------------------------------------------------------------------------------


def _link(link_id: str, node: Node, path: str, scene: dict[str, Any], ctx: _Context) -> LinkSpec:
    if not LINK_ID.fullmatch(link_id):
        raise node.error(path, "a link id must be letters, digits, '_', '.' or '-' (it names POSIX queues)")
    Fields(node, path, LINK_KEYS)  # unknown keys first, before the preset hides them
    model_node = node.value.get("model")
    merged = node
    if model_node is not None:
        merged = _merge(_load_preset(model_node, join_path(path, "model"), ctx), node)
    f = Fields(merged, path, LINK_KEYS)
    vehicle = f.get("vehicle", text)
    if vehicle not in scene["vehicles"]:
        raise f.child("vehicle").error(f.sub("vehicle"), f"no vehicle {vehicle!r} in the scene")
    backend = f.get("backend", choice(*BACKENDS), "sim")
    channels = scene["channels"]
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
    params = ModemParams(
        address=f.get("address", integer(0, BROADCAST - 1), -1),
        tx_channel=tx_channel,
        rx_channel=rx_channel,
        bitrate_bps=f.get("bitrate_bps", number(above=0), 1000.0),
        tx_delay_s=f.get("tx_delay_s", number(0), 0.0),
        rx_delay_s=f.get("rx_delay_s", number(0), 0.0),
        tx_jitter_s=f.get("tx_jitter_s", number(0), 0.0),
        rx_jitter_s=f.get("rx_jitter_s", number(0), 0.0),
        fifo_bytes=f.get("fifo_bytes", integer(1), 500_000),
        range_m=f.get("range_m", _range_pair, (0.0, math.inf)),
        error=f.get("error", _error_model, ErrorModel("packet", "0")),
        duplex=f.get("duplex", choice("half", "full"), "half"),
        promiscuous=f.get("promiscuous", boolean, False),
    )
    mac = f.get("mac", lambda n, p: _mac_spec(n, p, ctx.plugins), MacSpec("none"))
    try:
        problem = mac.mac_class.check(params, dict(mac.params))
    except Exception as exc:  # a plugin's own check() failed
        problem = f"the MAC's check failed: {type(exc).__name__}: {exc}"
    if problem:
        raise (f.child("mac") or f.node).error(f.sub("mac"), problem)
    packet = f.get("packet", _packet_class, "vl2b")
    model = None if model_node is None else str(model_node.value)
    options = _driver_options(f, backend)
    emulate = ()
    if "emulate" in f:
        if backend != "sim":
            raise f.child("emulate").error(f.sub("emulate"), "only a backend: sim link can emulate a modem")
        emulate = f.get("emulate", _emulate)
    addressing = f.get("addressing", choice(*ADDRESSING), "auto")
    return LinkSpec(link_id, vehicle, backend, model, params, mac, packet, node.file, node.line, options, emulate,
                    addressing)


_DRIVER_CHECKS: dict[str, Callable[[Node, str], Any]] = {
    "port": lambda node, path: _port(node, path),
    "baud": integer(50, 4_000_000),
    "im": boolean,
    "ack": boolean,
    "extended": boolean,
    "rtscts": boolean,
    "source_level": integer(0, 3),
    "gain": integer(0, 1),
    "im_retries": integer(0, 255),
    "command_timeout_s": number(above=0),
    "delivery_timeout_s": number(above=0),
    "queue_frames": integer(0, 100_000),
    "eol": choice("auto", "cr", "lf", "crlf"),
}


def _port(node: Node, path: str) -> str:
    """A device path (relative to the scene) or a pyserial URL that hilgate can open."""
    from ..drivers.port import port_problem

    value = node.value
    problem = port_problem(value) if isinstance(value, str) and value else None
    if problem:
        raise node.error(path, problem)
    value = text(node, path)
    return value if "://" in value else path_value(node, path)


def _driver_options(f: Fields, backend: str) -> tuple[tuple[str, Any], ...]:
    allowed = DRIVER_KEYS.get(backend, ())
    for key in ALL_DRIVER_KEYS:
        if key in f and key not in allowed:
            users = [b for b, keys in DRIVER_KEYS.items() if key in keys]
            raise f.child(key).error(f.sub(key), f"only for backend {' or '.join(users)} (this link is {backend})")
    if not allowed:
        return ()
    if "port" not in f:
        raise f.error(f"backend {backend} needs 'port' (a device such as /dev/ttyUSB0"
                      + (", or socket://HOST:9200)" if backend == "evologics" else ")"))
    return tuple((key, f.get(key, _DRIVER_CHECKS[key])) for key in allowed if key in f)


def _emulate(node: Node, path: str) -> tuple[tuple[str, Any], ...]:
    f = Fields(node, path, ("protocol", "pty", "tcp"))
    protocol = f.get("protocol", choice("evologics", "s100"))
    if ("pty" in f) == ("tcp" in f):
        raise f.error("give exactly one of pty (a path for the device link) or tcp (a loopback port)")
    if "tcp" in f:
        if protocol != "evologics":
            raise f.child("tcp").error(f.sub("tcp"), "only the EvoLogics modem speaks TCP; the S100 is serial")
        return (("protocol", protocol), ("tcp", f.get("tcp", integer(1, 65535))))
    return (("protocol", protocol), ("pty", f.get("pty", path_value)))


def _assign_addresses(links: dict[str, LinkSpec], nodes: dict[str, Node]) -> dict[str, LinkSpec]:
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
                raise nodes[link_id].error(f"links.{link_id}", "no free address left (0..254)")
            used.add(next_free)
            link = _replace_params(link, address=next_free)
        key = (link.params.rx_channel, link.params.address)
        if link.backend != "sim":
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
    from dataclasses import replace

    return replace(link, params=replace(link.params, **changes))


# -- flows ----------------------------------------------------------------------------------------


def _flow(node: Node, path: str, links: dict[str, LinkSpec], duration: float) -> FlowSpec:
    f = Fields(node, path, FLOW_KEYS)
    src = f.get("from", text)
    if src not in links:
        raise f.child("from").error(f.sub("from"), f"no link {src!r}; links: {', '.join(links)}")
    dst = f.get("to", text)
    if dst != "*":
        if dst not in links:
            raise f.child("to").error(f.sub("to"), f"no link {dst!r} (or \"*\" for broadcast)")
        if dst == src:
            raise f.child("to").error(f.sub("to"), "a flow cannot go to its own link")
        if links[dst].params.rx_channel != links[src].params.tx_channel:
            raise f.child("to").error(
                f.sub("to"),
                f"{dst!r} listens on channel {links[dst].params.rx_channel!r} but {src!r} transmits on "
                f"{links[src].params.tx_channel!r}: it can never hear this flow",
            )
    size = f.get("size_bytes", integer(1))
    if ("interval_s" in f) == ("rate_hz" in f):
        raise f.error("give exactly one of interval_s or rate_hz")
    if "interval_s" in f:
        interval = f.get("interval_s", number(above=0))
    else:
        interval = 1.0 / f.get("rate_hz", number(above=0))
    poisson = f.get("poisson", boolean, False)
    start = f.get("start_s", number(0), 0.0)
    stop = f.get("stop_s", number(0, allow_inf=True), math.inf)
    if stop <= start:
        raise f.child("stop_s").error(f.sub("stop_s"), f"must be after start_s ({start:g})")
    return FlowSpec(src, dst, size, interval, poisson, start, stop)


# -- the whole scene ------------------------------------------------------------------------------


def _validate(root: Node | None, file: str, plugins: Sequence[str] = (), preset_dirs: Sequence[str] = ()) -> Scene:
    if root is None:
        raise SceneError(file, 0, "", "the scene is empty")
    if root.is_map:  # top-level x-… keys hold YAML anchors for reuse (as in docker-compose): ignored
        root = Node({k: v for k, v in root.items() if not k.startswith("x-")}, root.file, root.line)
    f = Fields(root, "", TOP_KEYS)
    scene_dir = os.path.dirname(os.path.abspath(file)) if not file.startswith("<") else os.getcwd()
    ctx = _Context(scene_dir, tuple(preset_dirs), _load_plugins(f.child("plugins"), plugins))
    name = f.get("name", text, os.path.splitext(os.path.basename(file))[0])
    seed = f.get("seed", integer(0, 2**63 - 1), 1)
    duration = f.get("duration_s", number(above=0), 60.0)

    channels: dict[str, Channel] = {}
    channels_node = f.child("channels")
    if channels_node is None:
        raise f.error("missing required key 'channels' (e.g. acoustic: {speed_mps: 1500})")
    for cname, cnode in mapping(channels_node, "channels").items():
        cf = Fields(cnode, join_path("channels", cname), CHANNEL_KEYS)
        channels[cname] = Channel(cname, cf.get("speed_mps", number(above=0)), cf.get("min_delay_s", number(0), 0.0))
    if not channels:
        raise channels_node.error("channels", "define at least one channel")

    vehicles: dict[str, VehicleSpec] = {}
    vehicles_node = f.child("vehicles")
    if vehicles_node is None:
        raise f.error("missing required key 'vehicles'")
    for vname, vnode in mapping(vehicles_node, "vehicles").items():
        vehicles[vname] = _vehicle(vname, vnode, join_path("vehicles", vname))

    cameras: dict[str, CameraSpec] = {}
    cameras_node = f.child("cameras")
    if cameras_node is not None:
        for cname, cnode in mapping(cameras_node, "cameras").items():
            cameras[cname] = _camera(cname, cnode, join_path("cameras", cname), vehicles)
    for vname, vehicle in vehicles.items():
        for kind, params in (vehicle.pose.params if vehicle.pose.kind == "live" else ()):
            if kind != "aruco":
                continue
            options = dict(params)
            where = join_path(join_path(join_path("vehicles", vname), "pose"), "aruco")
            camera = cameras.get(options["camera"])
            if camera is None:
                raise vehicles_node.value[vname].error(where, f"no camera {options['camera']!r} under cameras:")
            if camera.fixed is not None and options["marker"] is None:
                raise vehicles_node.value[vname].error(where, "a fixed camera needs the vehicle's marker id")
            if camera.onboard is not None and camera.onboard[0] != vname:
                raise vehicles_node.value[vname].error(where, f"camera {camera.name!r} is on {camera.onboard[0]!r}")

    links_node = f.child("links")
    if links_node is None:
        raise f.error("missing required key 'links'")
    link_nodes = mapping(links_node, "links")
    context = {"channels": channels, "vehicles": vehicles}
    links = {lid: _link(lid, lnode, join_path("links", lid), context, ctx) for lid, lnode in link_nodes.items()}
    links = _assign_addresses(links, link_nodes)

    flows: list[FlowSpec] = []
    flows_node = f.child("flows")
    if flows_node is not None and flows_node.value is not None:
        for i, fnode in enumerate(items(flows_node, "flows")):
            flows.append(_flow(fnode, join_path("flows", i), links, duration))

    trace_file = None
    trace_poses = 1.0
    trace_node = f.child("trace")
    if trace_node is not None:
        tf = Fields(trace_node, "trace", ("file", "poses_s"))
        trace_file = tf.get("file", path_value, None)
        trace_poses = tf.get("poses_s", number(0), 1.0) or None
    return Scene(name, seed, duration, channels, vehicles, links, flows, trace_file, file, cameras, trace_poses)


def load_scene(path: str, overrides: Sequence[str] = (), *, plugins: Sequence[str] = (),
               preset_dirs: Sequence[str] = ()) -> Scene:
    """Load, override and validate the scene file at ``path``; every problem is one :class:`SceneError`.

    ``plugins``: ``--plugin`` entries (``.py`` files relative to the working directory, or module
    names), loaded besides the scene's own ``plugins:``; ``preset_dirs``: ``--preset-dir``
    directories a ``model:`` file may come from besides the scene's own directory."""
    root = load_file(path)
    for assignment in overrides:
        if root is None:
            root = Node({}, path, 0)
        apply_override(root, assignment)
    return _validate(root, path, plugins, preset_dirs)


def load_scene_text(text_: str, file: str = "<scene>", overrides: Sequence[str] = (), *,
                    plugins: Sequence[str] = (), preset_dirs: Sequence[str] = ()) -> Scene:
    """:func:`load_scene` for text; ``file`` names it in errors and its directory is the scene's."""
    root = load_text(text_, file)
    for assignment in overrides:
        if root is None:
            root = Node({}, file, 0)
        apply_override(root, assignment)
    return _validate(root, file, plugins, preset_dirs)


def scene_summary(scene: Scene) -> str:
    """A few lines for ``hilgate check``."""
    lines = [f"scene {scene.name!r}: {len(scene.channels)} channels, {len(scene.vehicles)} vehicles, "
             f"{len(scene.links)} links, {len(scene.flows)} flows, seed {scene.seed}, {scene.duration_s:g} s"]
    for link in scene.links.values():
        p = link.params
        channel = p.tx_channel if p.tx_channel == p.rx_channel else f"{p.tx_channel}->{p.rx_channel}"
        model = f" ({link.model})" if link.model else ""
        lines.append(f"  {link.id}: {link.backend}{model} on {link.vehicle}, addr {p.address}, {channel}, "
                     f"{p.bitrate_bps:g} bit/s, mac {link.mac.protocol}, packet {link.packet}")
    return "\n".join(lines)
