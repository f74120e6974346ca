"""JSON from clients, parsed with bounds: what a local user sends must not cost the loop a traceback.

``json.loads`` recurses once per nesting level, so a 30 000-deep line raises RecursionError (and
deeper ones can exhaust the C stack); a long line costs time in proportion.  :func:`loads` refuses
both before parsing, with :class:`JsonError` (a ValueError) saying why in one line.
"""

from __future__ import annotations

import json
import re
from typing import Any

MAX_DEPTH = 32
# A string runs to its closing quote, or to the end of the line if it has none: a string rule that
# failed there let the scan start again at the next quote, quadratic (``"`` + ``\\"`` x 32 000, 64 kB,
# held the loop 19 s).  Possessive, and ``.`` takes a newline too, so no match ever backtracks.
_BRACKETS_OR_STRINGS = re.compile(rb'"(?:[^"\\]++|\\.)*+(?:"|\\?\Z)|[\[\]{}]', re.DOTALL)


class JsonError(ValueError):
    """Not acceptable JSON from a client: too long, too deep, or not JSON."""


def depth(data: bytes) -> int:
    """Deepest nesting of arrays and objects, skipping brackets inside strings."""
    deepest = level = 0
    for match in _BRACKETS_OR_STRINGS.finditer(data):
        token = match.group()
        if token in (b"[", b"{"):
            level += 1
            if level > deepest:
                deepest = level
        elif token in (b"]", b"}"):
            level -= 1
    return deepest


def loads(data: bytes | str, max_bytes: int = 65536, max_depth: int = MAX_DEPTH) -> Any:
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else bytes(data)
    if len(raw) > max_bytes:
        raise JsonError(f"longer than {max_bytes} bytes")
    if depth(raw) > max_depth:
        raise JsonError(f"nested deeper than {max_depth} levels")
    try:
        return json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise JsonError(f"not JSON: {exc}") from None
    except RecursionError:  # pragma: no cover - the depth check comes first
        raise JsonError("nested too deeply") from None
