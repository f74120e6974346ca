"""A scene's ``apps:``: applications ``hilgate sim`` runs in-process on the model's clock.

    plugins: [pingpong.py]
    apps:
      - {class: pingpong:Ping, links: [a], params: {period_s: 10}}
      - {class: pingpong:Pong, name: echo, links: [b]}

``class`` is ``plugin:Class`` of a listed plugin (a subclass of :class:`hilgate.app.Application`);
``links`` the simulated links it uses (at least one); ``params`` any mapping (YAML values), handed to
the application as ``ctx.params``; ``name`` (default: the class name, numbered when repeated) seeds
its ``ctx.random``.  The daemon ignores ``apps:`` (``hilgate app`` runs an application against it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..core.application import Application
from .checks import Fields, items, join_path, mapping, quote, text
from .plugins import Plugin, class_from_origin, origin_of
from .yaml_nodes import Node

__all__ = ["AppSpec", "app_specs"]


@dataclass(frozen=True)
class AppSpec:
    name: str
    reference: str  # plugin:Class, as the scene wrote it
    links: tuple[str, ...]
    params: dict[str, Any] = field(default_factory=dict, hash=False)  # plain YAML values (ctx.params)
    cls: type | None = field(default=None, compare=False, repr=False)

    def __reduce__(self):
        """Pickled by where its class comes from (a reload is validated in another process)."""
        origin = None if self.cls is None else origin_of(self.cls)
        qualname = None if self.cls is None else self.cls.__qualname__
        return (_app_spec, (self.name, self.reference, self.links, self.params, origin, qualname))


def _app_spec(name, reference, links, params, origin, qualname) -> AppSpec:
    cls = None if origin is None else class_from_origin(origin, qualname)
    return AppSpec(name, reference, links, params, cls)


def _plain(node: Node) -> Any:
    """A YAML value without its file:line wrapping."""
    if node.is_map:
        return {key: _plain(child) for key, child in node.items()}
    if node.is_list:
        return [_plain(child) for child in node.value]
    return node.value


def app_specs(node: Node, plugins: dict[str, Plugin], links: dict[str, Any]) -> tuple[AppSpec, ...]:
    specs: list[AppSpec] = []
    names: dict[str, int] = {}
    for i, item in enumerate(items(node, "apps")):
        path = join_path("apps", i)
        f = Fields(item, path, ("class", "name", "links", "params"))
        reference = f.get("class", text)
        plugin_name, colon, class_name = reference.partition(":")
        plugin = plugins.get(plugin_name)
        if not colon or plugin is None:
            raise f.child("class").error(f.sub("class"), f"{quote(reference)} is not plugin:Class of a listed plugin "
                                                         "(list the .py file or module under plugins:)")
        # by name: the class the scene names, by its name
        cls = getattr(plugin.module, class_name, None) if class_name.isidentifier() else None
        if not (isinstance(cls, type) and issubclass(cls, Application)):
            raise f.child("class").error(f.sub("class"), f"{quote(reference)} is not an application (a subclass "
                                                         "of hilgate.app.Application)")
        link_nodes = items(f.child("links"), f.sub("links")) if "links" in f else []
        if not link_nodes:
            raise f.error("missing 'links': the simulated links the application uses")
        used = []
        for j, link_node in enumerate(link_nodes):
            link_id = text(link_node, join_path(f.sub("links"), j))
            link = links.get(link_id)
            if link is None:
                raise link_node.error(join_path(f.sub("links"), j), f"no link {link_id!r} in the scene")
            if link.backend != "sim":
                raise link_node.error(join_path(f.sub("links"), j), f"link {link_id!r} is not simulated "
                                      f"(backend {link.backend}): hilgate sim runs applications on simulated links")
            used.append(link_id)
        params = {}
        if "params" in f:
            mapping(f.child("params"), f.sub("params"))
            params = _plain(f.child("params"))
        default = class_name if class_name not in names else f"{class_name}{names[class_name] + 1}"
        names[class_name] = names.get(class_name, 0) + 1
        name = f.get("name", text, default)
        if any(spec.name == name for spec in specs):
            raise item.error(path, f"two applications are named {name!r}: give one a name:")
        specs.append(AppSpec(name, reference, tuple(used), params, cls))
    return tuple(specs)
