"""Reading validated values out of located YAML, one key at a time.

:class:`Fields` wraps one mapping: it refuses unknown keys up front (with a "did you mean" for
typos, because a misspelt key must never fall back silently to a default), and each ``get`` checks
one value with a small checker function that raises :class:`SceneError` naming file, line and key.
"""

from __future__ import annotations

import math
import os
import re
from typing import Any, Callable, Iterable, Sequence

from ..core.outputs import output_problem, pty_link_problem
from .yaml_nodes import Node, SceneError, one_line

MISSING: Any = object()

Checker = Callable[[Node, str], Any]


QUOTE = 60  # characters of a value quoted in a message


def quote(value: Any) -> str:
    """``repr(value)`` short enough for an error line (a scene may hold a 1 MB string or a 1 000-digit
    number; the message needs only its beginning)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10 ** QUOTE:
        return f"a number of {len(str(abs(value)))} digits"
    return one_line(repr(value), QUOTE)


def describe(node: Node) -> str:
    value = node.value
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if value is None:
        return "empty (null)"
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, str):
        return f"the text {quote(value)}"
    return quote(value)


def join_path(path: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else key


class Fields:
    def __init__(self, node: Node, path: str, known: Iterable[str]):
        if not node.is_map:
            raise node.error(path, f"must be a mapping of keys, not {describe(node)}")
        self.node = node
        self.path = path
        self.known = list(known)
        for key, child in node.items():
            if key not in self.known:
                raise child.error(join_path(path, key), unknown_key_message(key, self.known))

    def __contains__(self, key: str) -> bool:
        return key in self.node.value

    def child(self, key: str) -> Node | None:
        return self.node.value.get(key)

    def sub(self, key: str) -> str:
        return join_path(self.path, key)

    def get(self, key: str, check: Checker, default: Any = MISSING) -> Any:
        child = self.node.value.get(key)
        if child is None:
            if default is MISSING:
                raise self.node.error(self.path, f"missing required key {key!r}")
            return default
        return check(child, self.sub(key))

    def error(self, message: str) -> SceneError:
        return self.node.error(self.path, message)


def unknown_key_message(key: str, known: Sequence[str]) -> str:
    import difflib  # only for a scene with a mistake: not in every simulation's memory

    close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
    if close:
        return f"unknown key (did you mean {close[0]!r}?)"
    return f"unknown key; expected one of: {', '.join(known)}"


# -- checkers ------------------------------------------------------------------------------------


def number(minimum: float | None = None, maximum: float | None = None, *, above: float | None = None,
           allow_inf: bool = False) -> Checker:
    def check(node: Node, path: str) -> float:
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise node.error(path, f"must be a number, not {describe(node)}")
        try:
            value = float(value)
        except OverflowError:
            raise node.error(path, f"must be a finite number; {describe(node)} is too large") from None
        if math.isnan(value) or (math.isinf(value) and not allow_inf):
            raise node.error(path, f"must be a finite number, not {value}")
        if minimum is not None and value < minimum:
            raise node.error(path, f"must be at least {minimum:g}, not {value:g}")
        if above is not None and value <= above:
            raise node.error(path, f"must be greater than {above:g}, not {value:g}")
        if maximum is not None and value > maximum:
            raise node.error(path, f"must be at most {maximum:g}, not {value:g}")
        return value

    return check


def integer(minimum: int | None = None, maximum: int | None = None) -> Checker:
    def check(node: Node, path: str) -> int:
        value = node.value
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise node.error(path, f"must be a whole number, not {describe(node)}")
        if minimum is not None and value < minimum:
            raise node.error(path, f"must be at least {minimum}, not {quote(value)}")
        if maximum is not None and value > maximum:
            raise node.error(path, f"must be at most {maximum}, not {quote(value)}")
        return value

    return check


def text(node: Node, path: str) -> str:
    if not isinstance(node.value, str) or not node.value:
        raise node.error(path, f"must be a non-empty text, not {describe(node)}")
    return node.value


def boolean(node: Node, path: str) -> bool:
    if not isinstance(node.value, bool):
        raise node.error(path, f"must be true or false, not {describe(node)}")
    return node.value


def choice(*options: str) -> Checker:
    def check(node: Node, path: str) -> str:
        value = node.value
        if not isinstance(value, str) or value not in options:
            raise node.error(path, f"must be one of {', '.join(options)}, not {describe(node)}")
        return value

    return check


def vector(length: int = 3) -> Checker:
    item = number()

    def check(node: Node, path: str) -> tuple[float, ...]:
        if not node.is_list or len(node.value) != length:
            raise node.error(path, f"must be a list of {length} numbers like [x, y, z], not {describe(node)}")
        return tuple(item(child, join_path(path, i)) for i, child in enumerate(node.value))

    return check


def items(node: Node, path: str) -> list[Node]:
    if not node.is_list:
        raise node.error(path, f"must be a list, not {describe(node)}")
    return node.value


def matching(pattern: re.Pattern[str], should_be: str) -> Checker:
    """A text that ``pattern`` matches whole; anything else is refused as not what it ``should_be``
    (``"a host name is letters, digits…"``), the error saying what was given instead."""
    def check(node: Node, path: str) -> str:
        value = text(node, path)
        if not pattern.fullmatch(value):
            raise node.error(path, f"{should_be}, not {describe(node)}")
        return value

    return check


def one_or_more(check: Checker) -> Checker:
    """One value or a list of them (``connect: tcp/a:7447`` or ``connect: [tcp/a:7447, tcp/b:7447]``), each
    taken by ``check`` at its own path: a tuple."""
    def values(node: Node, path: str) -> tuple:
        nodes = [node] if isinstance(node.value, str) else items(node, path)
        return tuple(check(item, path if item is node else join_path(path, i)) for i, item in enumerate(nodes))

    return values


def mapping(node: Node, path: str) -> dict[str, Node]:
    if not node.is_map:
        raise node.error(path, f"must be a mapping of keys, not {describe(node)}")
    return node.value


# -- paths -----------------------------------------------------------------------------------------


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


def pty_path(node: Node, path: str) -> str:
    """Checker: where an emulated modem's pty link goes; nothing but a pty link may be there already
    (``pty: /etc/localtime`` would have removed a system file; :mod:`hilgate.core.outputs`)."""
    value = path_value(node, path)
    problem = pty_link_problem(value)
    if problem is not None:
        raise node.error(path, problem)
    return value


def trace_path(node: Node, path: str) -> str:
    """Checker: a trace file the scene asks for; absent, empty or a trace already (:mod:`hilgate.core.outputs`)."""
    value = path_value(node, path)
    problem = output_problem(value, "trace")
    if problem is not None:
        raise node.error(path, problem)
    return value
