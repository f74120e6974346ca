"""A link's ``mac:``: the protocol it names (built in, or a class of a listed plugin) and its parameters.

Each MAC class declares its scene keys in ``PARAMETERS`` (:class:`hilgate.models.mac.Param`); they
are checked here from that metadata, so a new MAC needs no change to the loader.  Resolving a name
never imports anything: plugins were loaded when the scene listed them.
"""

from __future__ import annotations

from typing import Any

from ..core.tables import merge_entry_points
from ..models.mac import Mac, Param
from ..models.macs import REGISTRY as MAC_REGISTRY
from .checks import Fields, boolean, integer, join_path, mapping, number, quote, text, unknown_key_message, vector
from .plugins import Plugin, classes_of
from .specs import MacSpec
from .yaml_nodes import Node

__all__ = ["mac_spec"]

# a lab's own MACs, installed as packages (hilgate.core.tables): the entry point's name is the scene's
merge_entry_points("hilgate.macs", MAC_REGISTRY, lambda row: isinstance(row, type) and issubclass(row, Mac),
                   name_of=lambda row: None)


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
        # by name: the class the scene names, by its name
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
    close = unknown_key_message(protocol, [*MAC_REGISTRY, *provided])
    guess = close[close.index("(did"):] if "(did you mean" in close else ""
    raise node.error(path, f"unknown MAC protocol {quote(protocol)}{' ' + guess if guess else ''}; built in: {', '.join(MAC_REGISTRY)}"
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


def mac_spec(node: Node, path: str, plugins: dict[str, Plugin]) -> MacSpec:
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
