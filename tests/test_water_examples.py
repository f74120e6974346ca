"""The shipped water examples (``examples/water/*.yaml``, issue 38): they load, their beam fans converge,
and what docs/channel-models.md says of them (written by ``docs/water_examples.py``) is what BELLHOP gives.

The fans are checked on each example's water with a coarser grid (one source depth, 20 depths, 50 ranges:
the fan's needs come from the water's extent and the frequency, which stay), against BELLHOP with twice
the beams; the slope's non-reciprocity is measured again with BELLHOP at the modems' depths and ranges.
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys

import numpy as np
import pytest

from bellhop_kit import ensure_program
from hilgate.channel.beams import judged_points
from hilgate.channel.prepare import ready_channels
from hilgate.models.bellhop_fields import TL_CAP
from hilgate.scene import load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = sorted(f[:-5] for f in os.listdir(os.path.join(ROOT, "examples", "water")) if f.endswith(".yaml"))
COARSER = ["channels.acoustic.water.grid.source_depths=1", "channels.acoustic.water.grid.depths=20",
           "channels.acoustic.water.grid.ranges=50", "channels.acoustic.water.grid.arrival_depths=5",
           "channels.acoustic.water.grid.arrival_ranges=5"]


@pytest.fixture(scope="module")
def measure():
    spec = importlib.util.spec_from_file_location("water_examples", os.path.join(ROOT, "docs", "water_examples.py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules["water_examples"] = module
    spec.loader.exec_module(module)
    return module


def test_the_examples_are_the_documented_three():
    assert EXAMPLES == ["munk", "slope", "summer"]
    for name in EXAMPLES:
        scene = load_scene(os.path.join(ROOT, "examples", "water", f"{name}.yaml"))
        assert scene.channels["acoustic"].water.beams == "auto"
        assert f"examples/water/{name}.yaml" in open(os.path.join(ROOT, "docs", "channel-models.md")).read()


@pytest.mark.parametrize("name", EXAMPLES)
def test_each_examples_fan_is_within_half_a_db_of_a_converged_run(name, measure, tmp_path):
    """The fan the example's water converges to (doubling it to there moved the TL by 0.5 dB or less at
    99.9 % of the grid: ``beams.py``) is within 0.5 dB of BELLHOP with twice its beams at every grid point
    that counts: heard by both, in the water (not in the sediment under the slope, where beams' tails
    leave numbers no modem can be at) and reached directly within the fan."""
    scene = load_scene(os.path.join(ROOT, "examples", "water", f"{name}.yaml"), COARSER)
    program = ensure_program()
    ready = ready_channels(scene.channels, scene.links, program=program, cache=str(tmp_path))
    (fields,) = ready["acoustic"].propagation.fields
    beams, change, _ = fields.fan
    assert change <= 0.5, (beams, change)
    water = scene.channels["acoustic"].water
    reference = measure.tl_run(water, fields.frequency_hz, 2 * beams - 1, program)[0]
    zs = water.source_grid()[0]
    ours = np.array([[fields.tl_db(r, zs, zr) for r in water.range_grid()] for zr in water.receiver_grid()])
    counted = judged_points(water, [zs])[0] & (reference < TL_CAP) & (ours < TL_CAP)
    assert counted.mean() > 0.5
    assert np.abs(ours - reference)[counted].max() <= 0.5, np.abs(ours - reference)[counted].max()


def test_the_documented_non_reciprocity_is_what_bellhop_gives(measure):
    """docs/channel-models.md quotes the slope example's non-reciprocity as docs/water_examples.py measured
    it (with the fan the example converged to): measured again, BELLHOP gives the very line."""
    text = open(os.path.join(ROOT, "docs", "channel-models.md"), encoding="utf-8").read()
    found = re.search(r"slope, non-reciprocity with (\d+) beams: ([^\n]+)", text)
    assert found, "docs/channel-models.md does not quote the slope's non-reciprocity"
    beams = int(found.group(1))
    water, hz = measure.water_of("slope")
    rows = measure.reciprocity(water, hz, beams, ensure_program())
    assert found.group(2).rstrip("`").strip() == measure.describe(rows)
    assert max(abs(d) for *_, d in rows) > 1.0  # it is not numerical noise: the flat water's is far smaller
