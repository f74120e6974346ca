"""Names that several rooms check the same way: a Zenoh key prefix is read from scenes (``zenoh:
prefix:``) and given by applications (``Link.open(..., prefix=...)``, ``--zenoh-prefix``)."""

from __future__ import annotations

import re

ZENOH_PREFIX = re.compile(r"[A-Za-z0-9_.-]{1,64}(/[A-Za-z0-9_.-]{1,64}){0,3}")
ZENOH_PREFIX_RULE = "a key prefix is one to four words of letters, digits, '_', '.' or '-' joined by '/'"


def zenoh_prefix_problem(value: object) -> str:
    """Why ``value`` is no Zenoh key prefix, or "" if it is one (no wildcard can reach a key expression)."""
    if not isinstance(value, str) or not ZENOH_PREFIX.fullmatch(value):
        return ZENOH_PREFIX_RULE
    return ""
