"""A damaged cache of BELLHOP's fields (issue 38): whatever happened to the file (cut short by a full disk
or a killed writer, a bit flipped by a bad sector or a careless hand), the command that meets it says so
in one warning and computes the fields again; it never stops on a traceback, and never uses what the
damage left.

The program is the real one (``bellhop_kit``) for a small field; the many damaged copies are judged with
a program that cannot run (``/bin/false``): a copy the cache takes must give the very fields written, one
it refuses must go to the program, with one warning.
"""

from __future__ import annotations

import logging
import os

import numpy as np
import pytest

from bellhop_kit import ensure_program
from hilgate.channel.runner import BellhopError, Program, prepare_fields
from hilgate.models.environment import Water

SMALL = Water(depth_m=50.0, sound_speed=((0.0, 1500.0), (50.0, 1500.0)), ranges=5, depths=5, source_depths=1,
              arrival_ranges=5, arrival_depths=5, beams=201)
FALSE = Program(("/bin/false",), "/bin/false")
LOGGER = "hilgate.channel"


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A cache holding the small field, its file's bytes, and the fields as they were computed."""
    cache = tmp_path_factory.mktemp("fields")
    fields = prepare_fields(SMALL, [10000.0], program=ensure_program(), cache=str(cache))[0]
    (name,) = os.listdir(cache)
    return cache / name, (cache / name).read_bytes(), fields


def _same(a, b) -> bool:
    return all(getattr(a, name) == getattr(b, name) for name in ("tl", "first", "spread")) and \
        a.frequency_hz == b.frequency_hz


def _judge(path, data: bytes, fields, caplog) -> str:
    """Put ``data`` in the cache and prepare: 'taken' (the very fields) or 'refused' (the program asked,
    one warning); anything else fails the test."""
    path.write_bytes(data)
    caplog.clear()
    try:
        got = prepare_fields(SMALL, [10000.0], program=FALSE, cache=str(path.parent))[0]
    except BellhopError:
        warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
        assert len(warnings) == 1, [r.getMessage() for r in warnings]
        assert str(path) in warnings[0].getMessage()
        return "refused"
    assert _same(got, fields), "a damaged cache file was taken for the fields"
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    return "taken"


def test_every_truncation_of_a_cache_file_is_refused_with_one_warning(written, caplog):
    caplog.set_level(logging.WARNING, logger=LOGGER)
    path, data, fields = written
    cuts = sorted(set(range(0, 64)) | set(range(0, len(data), max(1, len(data) // 150))) | {len(data) - 1})
    outcomes = {cut: _judge(path, data[:cut], fields, caplog) for cut in cuts}
    assert set(outcomes.values()) == {"refused"}, outcomes
    assert _judge(path, data, fields, caplog) == "taken"


def test_every_flipped_bit_of_a_cache_file_is_refused_with_one_warning(written, caplog):
    """One bit flipped in each of 400 bytes spread over the file (all of its first 64): what the damage
    left is never used, and nothing but a warning and a rebuild comes of it."""
    caplog.set_level(logging.WARNING, logger=LOGGER)
    path, data, fields = written
    rng = np.random.default_rng(38)
    places = sorted(set(range(min(64, len(data)))) | set(rng.choice(len(data), min(400, len(data)), replace=False)))
    refused = 0
    for i in places:
        damaged = bytearray(data)
        damaged[i] ^= 1 << int(rng.integers(0, 8))
        refused += _judge(path, bytes(damaged), fields, caplog) == "refused"
    assert refused == len(places)


def test_a_damaged_cache_file_is_one_warning_and_a_rebuild_in_a_command(tmp_path, monkeypatch, capsys, caplog):
    """The issue's case, end to end: ``hilgate channel prepare`` over a truncated file and then over one
    with a flipped bit logs one warning each (no traceback), computes the fields again with the real
    program, and leaves a good file: the next command neither warns nor runs BELLHOP.  (Under pytest the
    log goes to its capture, not to stderr.)"""
    from hilgate.cli import main

    caplog.set_level(logging.WARNING)

    program = ensure_program()
    cache = tmp_path / "cache"
    monkeypatch.setenv("HILGATE_CACHE", str(cache))
    monkeypatch.setenv("HILGATE_BELLHOP", " ".join(program.argv))
    scene = tmp_path / "w.yaml"
    scene.write_text("channels:\n  ac:\n    speed_mps: 1500\n    water:\n      depth_m: 50\n"
                     "      sound_speed: [[0, 1500], [50, 1500]]\n      beams: 201\n"
                     "      grid: {range_m: 500, ranges: 5, depths: 5, source_depths: 1, arrival_ranges: 5, "
                     "arrival_depths: 5}\n"
                     "vehicles: {a: {pose: {static: [0, 0, 10]}}}\nlinks: {la: {vehicle: a, address: 1}}\n")
    assert main(["channel", "prepare", str(scene)]) == 0
    capsys.readouterr()
    (name,) = os.listdir(cache / "bellhop")
    path = cache / "bellhop" / name
    good = path.read_bytes()
    flipped = bytearray(good)
    flipped[len(good) // 2] ^= 0x10
    for damaged in (good[:len(good) // 2], bytes(flipped)):
        path.write_bytes(damaged)
        caplog.clear()
        assert main(["channel", "prepare", str(scene)]) == 0
        err = capsys.readouterr().err
        warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
        assert len(warnings) == 1 and str(path) in warnings[0], warnings
        assert "Traceback" not in err
        assert path.read_bytes() == good
    monkeypatch.setenv("HILGATE_BELLHOP", "/bin/false")
    caplog.clear()
    assert main(["channel", "prepare", str(scene)]) == 0
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
