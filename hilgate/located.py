"""YAML with a file and line on every value, so that every scene error can say where it is.

PyYAML's plain ``safe_load`` forgets positions and silently keeps the last of two duplicate keys.
Here the document is composed into nodes and turned into :class:`Node` objects that remember
``file:line``; scalars are still constructed by PyYAML's safe constructor (ints, floats, booleans,
null, strings exactly as ``safe_load`` reads them), anchors and ``<<`` merges work, and a duplicate
key is an error.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Iterator

import yaml

__all__ = ["SceneError", "Node", "load_file", "load_text", "parse_scalar"]


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads YAML 1.2 floats such as ``2.25e7`` and ``1e-3`` (YAML 1.1 insists on
    a dot and a signed exponent, so PyYAML would read them as text and a scene would fail to load)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*\.?[0-9_]*|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


class SceneError(Exception):
    """A problem in a scene, printed as ``FILE:LINE: key.path: what is wrong``."""

    def __init__(self, file: str, line: int, path: str, message: str):
        self.file = file
        self.line = line
        self.path = path
        self.message = message
        super().__init__(str(self))

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        return f"{where}: {self.path}: {self.message}" if self.path else f"{where}: {self.message}"


@dataclass
class Node:
    """A YAML value and where it was written. ``value`` is a dict of str → Node, a list of Node,
    or a plain scalar."""

    value: Any
    file: str
    line: int

    @property
    def is_map(self) -> bool:
        return isinstance(self.value, dict)

    @property
    def is_list(self) -> bool:
        return isinstance(self.value, list)

    def plain(self) -> Any:
        """The value with every Node stripped (for comparisons and error messages)."""
        if isinstance(self.value, dict):
            return {k: v.plain() for k, v in self.value.items()}
        if isinstance(self.value, list):
            return [v.plain() for v in self.value]
        return self.value

    def items(self) -> Iterator[tuple[str, "Node"]]:
        return iter(self.value.items())

    def error(self, path: str, message: str) -> SceneError:
        return SceneError(self.file, self.line, path, message)


class _Builder:
    def __init__(self, text: str, file: str):
        self.file = file
        self.loader = _Loader(text)

    def build(self) -> Node | None:
        try:
            root = self.loader.get_single_node()
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            line = mark.line + 1 if mark else 0
            raise SceneError(self.file, line, "", f"not valid YAML: {exc.problem or exc.context}") from None
        except yaml.YAMLError as exc:
            raise SceneError(self.file, 0, "", f"not valid YAML: {exc}") from None
        finally:
            self.loader.dispose()
        if root is None:
            return None
        return self.convert(root, "")

    def convert(self, node: yaml.Node, path: str) -> Node:
        line = node.start_mark.line + 1
        if isinstance(node, yaml.MappingNode):
            try:
                self.loader.flatten_mapping(node)
            except yaml.MarkedYAMLError as exc:
                raise SceneError(self.file, line, "", f"bad merge key: {exc.problem}") from None
            result: dict[str, Node] = {}
            for key_node, value_node in node.value:
                key = self.scalar(key_node)
                if not isinstance(key, (str, int, float, bool)) or isinstance(key, bool):
                    raise SceneError(self.file, key_node.start_mark.line + 1, "", f"a key must be a name, not {key!r}")
                key = str(key)
                key_path = f"{path}.{key}" if path else key
                if key in result:
                    raise SceneError(
                        self.file, key_node.start_mark.line + 1, key_path,
                        f"duplicate key (first given on line {result[key].line})",
                    )
                converted = self.convert(value_node, key_path)
                converted.line = key_node.start_mark.line + 1  # where a reader looks for it
                result[key] = converted
            return Node(result, self.file, line)
        if isinstance(node, yaml.SequenceNode):
            return Node([self.convert(item, f"{path}[{i}]") for i, item in enumerate(node.value)], self.file, line)
        return Node(self.scalar(node), self.file, line)

    def scalar(self, node: yaml.Node) -> Any:
        if not isinstance(node, yaml.ScalarNode):
            raise SceneError(self.file, node.start_mark.line + 1, "", "a key must be a plain value")
        try:
            return self.loader.construct_object(node, deep=True)
        except yaml.YAMLError as exc:
            raise SceneError(self.file, node.start_mark.line + 1, "", f"bad value: {exc}") from None


def load_text(text: str, file: str = "<string>") -> Node | None:
    return _Builder(text, file).build()


def load_file(path: str) -> Node | None:
    try:
        with open(path, encoding="utf-8") as handle:
            text = handle.read()
    except OSError as exc:
        raise SceneError(path, 0, "", f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise SceneError(path, 0, "", f"not UTF-8 text: {exc.reason}") from None
    return load_text(text, path)


def parse_scalar(text: str) -> Any:
    """A command-line value read the way YAML would read it (``3`` → 3, ``none`` → 'none', ``[1,2]``)."""
    try:
        return yaml.load(text, Loader=_Loader)
    except yaml.YAMLError:
        return text
