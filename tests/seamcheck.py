"""Does a class provide what a ``typing.Protocol`` declares?  Checked on the class, without making one.

``isinstance`` with a runtime-checkable protocol only looks for names on an instance, and says nothing
about attributes a constructor sets or about the arguments of a method.  Here a member is present when
the class (or a base) defines it, annotates it, lists it in ``__slots__`` or assigns ``self.<name>`` in
one of its methods; a method must take every argument the protocol passes, in the same places, and
require no other.
"""

from __future__ import annotations

import ast
import functools
import inspect
import textwrap
from typing import Any, Protocol


def members(protocol: type) -> dict[str, Any]:
    """Name → what the protocol declares there: ``None`` for a data attribute, the function or property."""
    found: dict[str, Any] = {}
    for klass in reversed(protocol.__mro__):
        if klass is object or klass is Protocol or not getattr(klass, "_is_protocol", False):
            continue
        for name in vars(klass).get("__annotations__", {}):
            found.setdefault(name, None)
        for name, value in vars(klass).items():
            if name.startswith("_"):
                continue
            if isinstance(value, property) or inspect.isfunction(value):
                found[name] = value
    return found


@functools.cache
def _assigned(klass: type) -> frozenset[str]:
    """Names a class's own methods assign on ``self``."""
    try:
        source = textwrap.dedent(inspect.getsource(klass))
    except (OSError, TypeError):
        return frozenset()
    names = set()
    for node in ast.walk(ast.parse(source)):
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, (ast.AnnAssign, ast.AugAssign)) else []
        for target in targets:
            for leaf in ast.walk(target):
                if isinstance(leaf, ast.Attribute) and isinstance(leaf.value, ast.Name) and leaf.value.id == "self":
                    names.add(leaf.attr)
    return frozenset(names)


def _has(cls: type, name: str) -> bool:
    if hasattr(cls, name):
        return True
    for klass in cls.__mro__:
        if name in vars(klass).get("__annotations__", {}) or name in getattr(klass, "__slots__", ()):
            return True
        if klass is not object and name in _assigned(klass):
            return True
    return False


def _call_problem(declared: Any, given: Any) -> str | None:
    """Why ``given`` cannot be called as ``declared`` is (None: it can)."""
    want = list(inspect.signature(declared).parameters.values())[1:]  # without self
    try:
        have = list(inspect.signature(given).parameters.values())
    except (TypeError, ValueError):
        return None  # a builtin: nothing to read
    if have and have[0].name == "self":
        have = have[1:]
    varargs = any(p.kind is p.VAR_POSITIONAL for p in have)
    varkw = any(p.kind is p.VAR_KEYWORD for p in have)
    positional = [p for p in have if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    by_name = {p.name: p for p in have}
    for index, p in enumerate(want):
        if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD):
            if index >= len(positional) and not varargs:
                return f"takes no argument {p.name!r} (position {index + 1})"
        elif p.kind is p.KEYWORD_ONLY and p.name not in by_name and not varkw:
            return f"takes no keyword {p.name!r}"
    passed = {p.name for p in want}
    extra = [p.name for i, p in enumerate(positional) if i >= len(want) and p.default is p.empty]
    extra += [p.name for p in have if p.kind is p.KEYWORD_ONLY and p.default is p.empty and p.name not in passed]
    if extra:
        return f"requires {', '.join(extra)}, which the protocol never passes"
    return None


def missing(cls: type, protocol: type) -> list[str]:
    """What ``cls`` lacks of ``protocol`` (empty: it satisfies it)."""
    problems = []
    for name, declared in members(protocol).items():
        if not _has(cls, name):
            problems.append(f"{cls.__qualname__}.{name}: missing ({protocol.__qualname__} declares it)")
            continue
        if inspect.isfunction(declared):
            given = inspect.getattr_static(cls, name, None)
            if isinstance(given, (staticmethod, classmethod)):
                given = given.__func__
            if given is None or not callable(given):
                if given is None and name in _assigned_anywhere(cls):
                    continue  # a callable the constructor sets
                problems.append(f"{cls.__qualname__}.{name}: not a method")
                continue
            problem = _call_problem(declared, given)
            if problem:
                problems.append(f"{cls.__qualname__}.{name}: {problem}")
    return problems


def _assigned_anywhere(cls: type) -> set[str]:
    return set().union(*(_assigned(klass) for klass in cls.__mro__ if klass is not object))
