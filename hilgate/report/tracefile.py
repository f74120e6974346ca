"""Reading a trace that may be damaged: the one reader ``hilgate report`` and ``hilgate fit`` share.

A trace is JSON lines the daemon wrote, but what reaches these tools may have been cut, edited,
concatenated or replaced by anything at all.  Either tool answers with a result or with one line
naming the line number and what is wrong in it (:class:`TraceError`), in time linear in the file:

- a line is at most ``MAX_LINE_BYTES`` (read in bounded pieces, so a file without newlines costs no
  more memory than that), UTF-8, one JSON object, nested at most as deep as Python's parser allows;
- **one rule for numbers**: ``NaN``, ``Infinity`` and numbers too large for a float (``1e999``) are
  refused wherever they are in a line, and a time, size or coordinate a tool uses must be at most
  ``MAX_NUMBER`` in size (a float of 1e300 seconds would break every axis);
- the last line may be cut short (the daemon was killed while writing it): without its newline and
  not JSON, it is skipped;
- lines of events a tool does not know are skipped; the fields a tool uses are checked with the
  helpers here (:func:`number`, :func:`count`, :func:`text`, …), each error naming the line.
"""

from __future__ import annotations

import json
import math
from typing import Any, Iterator

__all__ = ["TraceError", "MAX_LINE_BYTES", "MAX_NUMBER", "read_lines", "number", "count", "text", "key",
           "position", "optional_number", "describe", "printable"]

MAX_LINE_BYTES = 32 << 20
"""A daemon's longest lines are its ``run``/``reload`` lines (about 0.5 KB per link)."""

MAX_NUMBER = 1e15
"""Times beyond 31 million years, sizes beyond a petabyte: no run has them, every axis breaks on them."""


class TraceError(RuntimeError):
    """A trace a tool cannot read: one line, ``FILE:LINE: what is wrong``."""


class _Refused(ValueError):
    pass


def _float(literal: str) -> float:
    value = float(literal)
    if not math.isfinite(value):
        raise _Refused(f"the number {literal[:24]} is too large for a float")
    return value


def _constant(literal: str) -> float:
    raise _Refused(f"{literal} is not a number a trace may hold")


def printable(name: str, limit: int = 80) -> str:
    """A name from a trace, safe to print on a terminal (control characters escaped) and short."""
    out = "".join(c if c.isprintable() else repr(c)[1:-1] for c in name[:limit])
    return out + ("…" if len(name) > limit else "")


def describe(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if isinstance(value, (dict, list)):
        return "an object" if isinstance(value, dict) else "a list"
    text_ = json.dumps(value, ensure_ascii=False) if isinstance(value, str) else repr(value)
    return text_ if len(text_) <= 40 else text_[:37] + "..."


def raw_lines(path: str, error: type[TraceError] = TraceError) -> Iterator[tuple[int, bytes, bool]]:
    """(line number, bytes, cut) of every line of a trace file, read at most ``MAX_LINE_BYTES`` + 1 bytes at
    a time (so a longer line comes without its newline); ``cut`` is true for a last line without its
    newline (a write a SIGKILL cut short).  A file that cannot be opened or read raises ``error``."""
    try:
        handle = open(path, "rb")
    except OSError as exc:
        raise error(f"cannot read trace {path}: {exc.strerror}") from None
    with handle:
        number = 0
        while True:
            try:
                raw = handle.readline(MAX_LINE_BYTES + 1)
            except OSError as exc:
                raise error(f"cannot read trace {path}: {exc.strerror}") from None
            if not raw:
                return
            number += 1
            yield number, raw, not raw.endswith(b"\n") and not handle.peek(1)


def read_lines(path: str, first: int = 1, last: int | None = None) -> Iterator[tuple[int, dict]]:
    """(line number, event) of every line from ``first`` to ``last`` (1-based, inclusive)."""
    for number, raw, cut in raw_lines(path):
        if not raw.endswith(b"\n") and len(raw) > MAX_LINE_BYTES:
            raise TraceError(f"{path}:{number}: longer than {MAX_LINE_BYTES} bytes (not a trace line)")
        if number < first:
            continue
        if last is not None and number > last:
            return
        if not raw.strip():
            continue
        try:
            event = _parse(raw)
        except _Refused as exc:
            if cut:
                return  # the last line, cut short by a SIGKILL
            raise TraceError(f"{path}:{number}: {exc}") from None
        if not isinstance(event, dict):
            raise TraceError(f"{path}:{number}: not a JSON object but {describe(event)}")
        yield number, event


def _parse(raw: bytes) -> Any:
    try:
        line = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise _Refused("not UTF-8 text") from None
    try:
        return json.loads(line, parse_float=_float, parse_constant=_constant)
    except _Refused:
        raise
    except RecursionError:
        raise _Refused("nested too deeply") from None
    except json.JSONDecodeError as exc:
        raise _Refused(f"not a JSON line ({exc.msg})") from None
    except ValueError:  # an integer of more digits than Python converts (4300)
        raise _Refused("a number of thousands of digits is not a number a trace may hold") from None


# -- the fields a tool uses ------------------------------------------------------------------------


def key(event: dict, name: str, where: str) -> Any:
    if name not in event:
        raise TraceError(f"{where}: no {name!r} in a {describe(event.get('ev'))} line")
    return event[name]


def number(event: dict, name: str, where: str, default: Any = ...) -> float:
    """A finite number of at most ``MAX_NUMBER`` (``default`` when absent, if given)."""
    if default is not ... and name not in event:
        return default
    value = key(event, name, where)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TraceError(f"{where}: {name!r} must be a number, not {describe(value)}")
    if not -MAX_NUMBER <= value <= MAX_NUMBER:
        raise TraceError(f"{where}: {name!r} = {describe(value)} is beyond any run (at most {MAX_NUMBER:g})")
    return float(value)


def optional_number(event: dict, name: str, where: str) -> float | None:
    """A number, or None when absent or null."""
    if event.get(name) is None:
        return None
    return number(event, name, where)


def count(event: dict, name: str, where: str, default: Any = ...) -> int:
    """A whole number from 0 to ``MAX_NUMBER``."""
    if default is not ... and name not in event:
        return default
    value = key(event, name, where)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_NUMBER:
        raise TraceError(f"{where}: {name!r} must be a whole number from 0 to {MAX_NUMBER:g}, not {describe(value)}")
    return value


def text(event: dict, name: str, where: str, default: Any = ...) -> str:
    if default is not ... and event.get(name) is None:
        return default
    value = key(event, name, where)
    if not isinstance(value, str):
        raise TraceError(f"{where}: {name!r} must be a text, not {describe(value)}")
    return value


def position(event: dict, name: str, where: str) -> list[float] | None:
    """A position ``[x, y, z]`` in metres, or None (the vehicle's pose was unknown)."""
    value = event.get(name)
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != 3 or any(
            isinstance(c, bool) or not isinstance(c, (int, float)) or not -MAX_NUMBER <= c <= MAX_NUMBER
            for c in value):
        raise TraceError(f"{where}: {name!r} must be [x, y, z] in metres or null, not {describe(value)}")
    return [float(c) for c in value]
