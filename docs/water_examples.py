#!/usr/bin/env python3
"""The figures docs/channel-models.md gives for the shipped water examples (``examples/water/*.yaml``):

- the beam fan each example's water converges to (``beams: auto``, ``hilgate/channel/beams.py``), how far
  the last doubling moved the TL, and how far the fan of 1 001 beams used before issue 38 was from it;
- the slope's non-reciprocity: BELLHOP's bathymetry is depth against range *from the sender*, so a pair
  over a slope sees the bottom rise away from whichever modem sends, and A → B and B → A differ.
  Measured with BELLHOP itself (no grid, no lookup) at the modems' depths and ranges of the slope example,
  and, as the numerical floor, on the flat summer example.

    python docs/water_examples.py            # prepares the examples' fields (minutes each, once: cached)

BELLHOP is the checkout's pelagic (``make .venv-bellhop/.installed``) or ``HILGATE_BELLHOP``.  The tests
(``tests/test_water_examples.py``) measure the non-reciprocity again with :func:`reciprocity`.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from hilgate.channel.beams import judged_points, judged_sources  # noqa: E402
from hilgate.channel.envfile import TL_RUN, bty_text, env_text  # noqa: E402
from hilgate.channel.prepare import frequencies_of, ready_channels  # noqa: E402
from hilgate.channel.runner import Program, _run, find_program  # noqa: E402
from hilgate.channel.shdfile import read_shd  # noqa: E402
from hilgate.models.bellhop_fields import TL_CAP  # noqa: E402
from hilgate.models.environment import Water  # noqa: E402
from hilgate.scene import load_scene  # noqa: E402

EXAMPLES = ("summer", "slope", "munk")
MODEM_DEPTHS = (10.0, 20.0, 30.0, 40.0, 50.0)
"""The slope example's modems: the buoy at 10 m, the AUV between 20 and 50 m."""
PAIR_RANGES = tuple(float(r) for r in range(500, 3501, 500))
"""Out to the 18/34 modem's 3 500 m."""


def example(name: str):
    return load_scene(os.path.join(ROOT, "examples", "water", f"{name}.yaml"))


def water_of(name: str) -> tuple[Water, float]:
    """An example's water and the frequency its pairs use."""
    scene = example(name)
    (channel,) = [c for c in scene.channels.values() if c.water is not None]
    (hz,) = frequencies_of(channel, scene.links)
    return channel.water, hz


def tl_run(water: Water, hz: float, beams: int, program: Program, sources: list[float] | None = None,
           depths: list[float] | None = None, ranges: list[float] | None = None) -> np.ndarray:
    """BELLHOP's incoherent TL [source][depth][range] with a fan of ``beams``, one source depth a run, on the
    water's grid or at the ``depths`` and ``ranges`` given."""
    water = dataclasses.replace(water, run="incoherent", beams=beams)
    bty = bty_text(water) if water.bathymetry else None
    planes = []
    for zs in (sources if sources is not None else water.source_grid()):
        lines = env_text(water, hz, TL_RUN, sources=[zs]).splitlines()
        if depths is not None:
            at = lines.index(str(water.depths))
            lines[at:at + 4] = [str(len(depths)), " ".join(repr(float(z)) for z in depths) + " /",
                                str(len(ranges)), " ".join(repr(float(r) / 1000.0) for r in ranges) + " /"]
        with tempfile.TemporaryDirectory() as workdir:
            shade = read_shd(_run(program, workdir, "tl", "\n".join(lines) + "\n", bty, ".shd"))
        planes.append(shade.transmission_loss_db()[0])
    return np.stack(planes)


def reciprocity(water: Water, hz: float, beams: int, program: Program, depths=MODEM_DEPTHS,
                ranges=PAIR_RANGES) -> list[tuple[float, float, float, float]]:
    """TL(A → B) − TL(B → A) for every pair of distinct depths at every range, both modems above the
    bottom there: [(range, depth A, depth B, difference dB)], A the shallower."""
    tl = tl_run(water, hz, beams, program, sources=list(depths), depths=list(depths), ranges=list(ranges))
    out = []
    for k, r in enumerate(ranges):
        for i, za in enumerate(depths):
            for j, zb in enumerate(depths):
                if za < zb < water.bottom_at(r) and max(tl[i, j, k], tl[j, i, k]) < TL_CAP:
                    out.append((r, za, zb, float(tl[i, j, k] - tl[j, i, k])))
    return out


def describe(rows) -> str:
    diffs = np.abs([d for *_, d in rows])
    r, za, zb, d = max(rows, key=lambda row: abs(row[3]))
    return (f"{len(rows)} pairs: |TL(A→B) − TL(B→A)| median {np.median(diffs):.2f} dB, 90 % within "
            f"{np.percentile(diffs, 90):.2f} dB, largest {abs(d):.2f} dB (A at {za:g} m, B at {zb:g} m, {r:g} m apart)")


def main() -> int:
    program = find_program()
    fans = {}
    print(f"water examples, {time.strftime('%Y-%m-%d')}, BELLHOP: {program}")
    for name in EXAMPLES:
        scene = example(name)
        start = time.monotonic()
        ready = ready_channels(scene.channels, scene.links, program=program)
        (fields,) = [f for c in ready.values() if c.water is not None for f in c.propagation.fields]
        beams, change, largest = fields.fan
        fans[name] = beams
        water, hz = water_of(name)
        sources = [water.source_grid()[i] for i in judged_sources(water.source_depths)]
        converged = tl_run(water, hz, beams, program, sources=sources)
        before = tl_run(water, hz, 1001, program, sources=sources)
        counted = judged_points(dataclasses.replace(water, run="incoherent"), sources)
        both = (converged < TL_CAP) & (before < TL_CAP) & counted
        off = np.zeros(both.shape)
        off[both] = before[both] - converged[both]
        at = np.unravel_index(int(np.argmax(np.abs(off))), off.shape)
        where = (sources[at[0]], water.receiver_grid()[at[1]], water.range_grid()[at[2]])
        print(f"{name}: {hz / 1000:g} kHz, {beams} beams (the last doubling moved the TL by {change:.2f} dB at "
              f"99.9 % of the grid, {largest:.2f} dB at most), prepared in {time.monotonic() - start:.0f} s (or from "
              f"the cache); 1 001 beams against it: {off[at]:+.2f} dB at worst (source {where[0]:g} m, receiver "
              f"{where[1]:g} m, {where[2]:g} m), {np.quantile(np.abs(off[both]), 0.999):.2f} dB at 99.9 %, median "
              f"{np.median(np.abs(off[both])):.2f} dB")
    for name in ("slope", "summer"):
        water, hz = water_of(name)
        rows = reciprocity(water, hz, fans[name], program)
        print(f"{name}, non-reciprocity with {fans[name]} beams: {describe(rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
