"""``hilgate channel prepare SCENE``: BELLHOP's fields of a scene's channels with water, into the cache."""

from __future__ import annotations

import argparse
import math

from .options import add_scene_args

NAME = "channel"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate channel``'s parser, among ``sub``'s."""
    p = sub.add_parser("channel", help="channels that know the water: 'prepare' computes BELLHOP's fields of a "
                                        "scene's channels with water into the cache (with a progress bar)")
    p.add_argument("action", choices=("prepare",))
    add_scene_args(p)
    p.add_argument("--bellhop", metavar="COMMAND", help="the BELLHOP program (default: HILGATE_BELLHOP, "
                   "bellhop.exe on the PATH, or the checkout's .venv-bellhop)")
    return p


def run(args: argparse.Namespace) -> int:
    """``hilgate channel prepare SCENE``: BELLHOP's fields of every channel with water, into the cache."""
    from ..channel.prepare import frequencies_of, ready_channels
    from ..channel.runner import bar, cache_dir, find_program
    from ..scene.load import load_scene

    scene = load_scene(args.scene, args.overrides, plugins=args.plugins, preset_dirs=args.preset_dirs)
    watery = {name: c for name, c in scene.channels.items() if c.water is not None}
    if not watery:
        print(f"{args.scene}: no channel has water: nothing to prepare")
        return 0
    program = find_program(args.bellhop) if args.bellhop else None
    ready = ready_channels(watery, scene.links, program=program, progress=bar())
    for name, channel in watery.items():
        hz = ", ".join(f"{f / 1000:g}" for f in sorted(frequencies_of(channel, scene.links)))
        fans = "; ".join(_fan_line(fields) for fields in ready[name].propagation.fields)
        print(f"channel {name}: BELLHOP fields at {hz} kHz ready in {cache_dir()} ({fans})")
    return 0


def _fan_line(fields) -> str:
    """How many beams a field was traced with, and how converged (``hilgate/channel/beams.py``)."""
    khz = f"{fields.frequency_hz / 1000:g} kHz"
    if fields.fan is None:
        return khz
    beams, change, largest = fields.fan
    if math.isnan(change):  # the scene gave the fan
        return f"{khz}: {beams} beams as given" if beams else f"{khz}: as many beams as BELLHOP chose"
    return (f"{khz}: {beams} beams; doubling to them moved the TL by {change:.2f} dB or less at 99.9 % of the "
            f"grid, {largest:.2f} dB at most")
