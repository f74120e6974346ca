"""Loading a scene whole: read the file, apply ``--set`` overrides, validate every section, return a
:class:`~hilgate.scene.specs.Scene`.

A scene is validated completely before anything is built from it, so a bad scene never half-starts
(and a bad reload never disturbs the running one).  Every error is a :class:`SceneError` printed as
``FILE:LINE: key.path: what is wrong``.  The format is DESIGN.md's "Scene file" section; each section
is read by its own module (:mod:`.vehicles`, :mod:`.links`, :mod:`.flows`), this one holds the
top-level keys, the channels, the plugins and the order in which the sections are read.
"""

from __future__ import annotations

import logging
import os
from typing import Sequence

from ..models.flows import FlowSpec
from ..models.medium import Channel
from .checks import Fields, base_dir, integer, items, join_path, mapping, number, quote, text, trace_path
from .app_spec import app_specs
from .flow_spec import flow_spec
from .hosts import resolve_hosts, zenoh_spec
from .modem_limits import describe_limits
from .links import Context, assign_addresses, link_spec
from .overrides import apply_override
from .plugins import Plugin, PluginError, load_plugin
from .ros2 import check_ros2_names, ros2_spec
from .specs import CameraSpec, Scene, VehicleSpec
from .channels import channel_spec
from .in_water import check_modems_in_water
from .vehicles import camera_spec, check_camera_references, vehicle_spec
from .yaml_nodes import Node, SceneError, load_file, load_text

__all__ = ["TOP_KEYS", "load_scene", "load_scene_text", "scene_summary"]

log = logging.getLogger(__name__)

TOP_KEYS = ("name", "seed", "duration_s", "plugins", "channels", "vehicles", "links", "flows", "trace", "cameras",
            "zenoh", "apps", "ros2")


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


def _validate(root: Node | None, file: str, plugins: Sequence[str] = (), preset_dirs: Sequence[str] = ()) -> Scene:
    if root is None:
        raise SceneError(file, 0, "", "the scene is empty")
    if root.is_map:  # top-level x-… keys hold YAML anchors for reuse (as in docker-compose): ignored
        root = Node({k: v for k, v in root.items() if not k.startswith("x-")}, root.file, root.line)
    f = Fields(root, "", TOP_KEYS)
    scene_dir = os.path.dirname(os.path.abspath(file)) if not file.startswith("<") else os.getcwd()
    ctx = Context(scene_dir, tuple(preset_dirs), _load_plugins(f.child("plugins"), plugins))
    name = f.get("name", text, os.path.splitext(os.path.basename(file))[0])
    seed = f.get("seed", integer(0, 2**63 - 1), 1)
    duration = f.get("duration_s", number(above=0), 60.0)

    channels = _channels(f)

    vehicles, cameras = _vehicles_and_cameras(f)

    links_node = f.child("links")
    if links_node is None:
        raise f.error("missing required key 'links'")
    link_nodes = mapping(links_node, "links")
    context = {"channels": channels, "vehicles": vehicles}
    links = {lid: link_spec(lid, lnode, join_path("links", lid), context, ctx) for lid, lnode in link_nodes.items()}
    links = assign_addresses(links, link_nodes)
    check_modems_in_water(channels, f.child("vehicles"), links)
    hosts, links, vehicles, cameras = resolve_hosts(links, vehicles, cameras, link_nodes, root)
    apps_node = f.child("apps")
    apps = () if apps_node is None or apps_node.value is None else app_specs(apps_node, ctx.plugins, links)
    zenoh_node = f.child("zenoh")
    zenoh = None if zenoh_node is None else zenoh_spec(zenoh_node)
    ros2_node = f.child("ros2")
    ros2 = None if ros2_node is None else ros2_spec(ros2_node)
    check_ros2_names(links, vehicles if ros2 is not None and (ros2.poses or ros2.tf) else {}, root)

    flows: list[FlowSpec] = []
    flows_node = f.child("flows")
    if flows_node is not None and flows_node.value is not None:
        for i, fnode in enumerate(items(flows_node, "flows")):
            flows.append(flow_spec(fnode, join_path("flows", i), links, duration))

    trace_file = None
    trace_poses = 1.0
    trace_node = f.child("trace")
    if trace_node is not None:
        tf = Fields(trace_node, "trace", ("file", "poses_s"))
        trace_file = tf.get("file", trace_path, None)
        trace_poses = tf.get("poses_s", number(0), 1.0) or None
    return Scene(name, seed, duration, channels, vehicles, links, flows, trace_file, file, cameras, trace_poses,
                 hosts, zenoh, apps, ros2)


def _channels(f: Fields) -> dict[str, Channel]:
    """The scene's ``channels:`` (at least one)."""
    channels: dict[str, Channel] = {}
    channels_node = f.child("channels")
    if channels_node is None:
        raise f.error("missing required key 'channels' (e.g. acoustic: {speed_mps: 1500})")
    for cname, cnode in mapping(channels_node, "channels").items():
        channels[cname] = channel_spec(cname, cnode)
    if not channels:
        raise channels_node.error("channels", "define at least one channel")
    return channels


def _vehicles_and_cameras(f: Fields) -> tuple[dict[str, VehicleSpec], dict[str, CameraSpec]]:
    """The scene's ``vehicles:`` and ``cameras:``, each camera's vehicles checked."""
    vehicles: dict[str, VehicleSpec] = {}
    vehicles_node = f.child("vehicles")
    if vehicles_node is None:
        raise f.error("missing required key 'vehicles'")
    for vname, vnode in mapping(vehicles_node, "vehicles").items():
        vehicles[vname] = vehicle_spec(vname, vnode, join_path("vehicles", vname))

    cameras: dict[str, CameraSpec] = {}
    cameras_node = f.child("cameras")
    if cameras_node is not None:
        for cname, cnode in mapping(cameras_node, "cameras").items():
            cameras[cname] = camera_spec(cname, cnode, join_path("cameras", cname), vehicles)
    check_camera_references(vehicles, cameras, vehicles_node)
    return vehicles, cameras


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
        line = (f"  {link.id}: {link.backend}{model} on {link.vehicle}, addr {p.address}, {channel}, "
                f"{p.bitrate_bps:g} bit/s, mac {link.mac.protocol}, packet {link.packet}")
        emulate = dict(link.emulate)
        if emulate:
            where = f"pty {emulate['pty']}" if emulate.get("pty") else f"TCP port {emulate.get('tcp')}"
            line += f", emulates {emulate.get('protocol')} at {where}"
        options = dict(link.options)
        port = options.get("port")
        if options.get("modem_host"):  # a UnetStack modem's API (fjåge's port 1100 unless given)
            line += f", modem at {options['modem_host']}:{port or 1100}"
        elif port:
            line += f", port {port}"
        if link.unet:
            door = dict(link.unet)
            line += f", UnetStack door at {door['host']}:{door['tcp']}"
        if link.host:
            line += f", host {link.host}"
        lines.append(line)
        limits = describe_limits(link)
        if limits is not None:
            lines.append(f"    {limits}")
    return "\n".join(lines)
