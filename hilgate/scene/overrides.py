"""``--set KEY.PATH=VALUE``: change a loaded scene's YAML before it is validated.

Overrides edit the located tree (values set here say ``--set`` where a file line would be), so the
scene is then validated exactly as if the file had said it, with the same messages.
"""

from __future__ import annotations

from typing import Any

from .checks import describe, join_path
from .yaml_nodes import MAX_DEPTH, Node, SceneError, parse_scalar

__all__ = ["apply_override"]


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
