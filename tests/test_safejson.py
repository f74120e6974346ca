"""hilgate.core.safejson's depth check, which every JSON line from a client or a peer passes
(GLI socket messages and Zenoh door commands up to 64 kB, control lines, a peer's meta and poses):
it must cost one pass over the line whatever the line holds.  Its string rule used to fail on a
string that never ends, and the scan then started again at the next quote: ``"`` + ``\\"`` x 32 000
(64 kB) cost 19 s of the daemon's loop, quadratic in the length."""

from __future__ import annotations

import pytest

from hilgate.core import safejson

N = 20000


@pytest.mark.parametrize("line", [
    b'"' + b'\\"' * N,              # escaped quotes, no end: each quote started a scan to the end
    b'"' + b'\\"' * N + b"\\",      # the same, with a lone backslash last
    b'"' + b'\\"' * N + b"\\\n",    # a backslash before a newline (which "." does not match)
    b'["' + b'\\"' * N + b"\\\n\"]",
], ids=["no_end", "lone_backslash", "backslash_newline", "backslash_newline_closed"])
def test_a_string_that_never_ends_is_scanned_once(line):
    """One match from the opening quote to the end (or its closing quote): no position is scanned
    twice, so the check is linear (the loop is never held by one line)."""
    strings = [m for m in safejson._BRACKETS_OR_STRINGS.finditer(line) if m.group().startswith(b'"')]
    assert len(strings) == 1
    assert strings[0].start() == line.index(b'"')


def test_depth_counts_brackets_outside_strings_only():
    assert safejson.depth(b'{"a": "[[[{{", "b": [[1], "\\"]]"]}') == 3
    assert safejson.depth(b'[[["x\\\\"]]]') == 3  # an escaped backslash, then the closing quote
    assert safejson.depth(b"[" * 40 + b'"' + b'\\"' * 100) == 40  # brackets before a string that never ends


def test_a_hostile_line_is_refused_with_a_json_error():
    with pytest.raises(safejson.JsonError):
        safejson.loads(b"[" * 40 + b'"' + b'\\"' * N)
    with pytest.raises(safejson.JsonError):
        safejson.loads(b'"' + b'\\"' * N)
    assert safejson.loads(b'{"a": ["\\"]"]}') == {"a": ['"]']}
