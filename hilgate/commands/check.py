"""``hilgate check SCENE``: a scene validated, what it contains, its queues against this user's limits and the
link budget of every pair."""

from __future__ import annotations

import argparse

from .options import add_scene_args

NAME = "check"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate check``'s parser, among ``sub``'s."""
    p = sub.add_parser("check", help="validate a scene file and print what it contains and what its error "
                                      "models mean (SNR, PER now, where PER crosses 0.1 and 0.9)")
    add_scene_args(p)
    p.add_argument("--frame-bytes", type=int, metavar="N",
                   help="PER of frames of N bytes (default: the size of the sender's first flow, else 64)")
    p.add_argument("--budget-rows", type=int, default=50, metavar="N",
                   help="show at most N pairs in the link budget (default 50; 0: all)")
    p.add_argument("--bellhop", metavar="COMMAND", help="the BELLHOP program for channels with water (default: "
                   "HILGATE_BELLHOP, bellhop.exe on the PATH, or the checkout's .venv-bellhop)")
    return p


def run(args: argparse.Namespace) -> int:
    from ..scene.load import load_scene, scene_summary

    from ..sim.budget import format_budget, link_budget

    scene = load_scene(args.scene, args.overrides, plugins=args.plugins, preset_dirs=args.preset_dirs)
    print(scene_summary(scene))
    print(_queue_budget(scene))
    limit = None if args.budget_rows == 0 else args.budget_rows
    channels = None
    if any(channel.water is not None for channel in scene.channels.values()):
        from ..channel.prepare import ready_channels
        from ..channel.runner import bar, find_program

        program = find_program(args.bellhop) if args.bellhop else None
        channels = ready_channels(scene.channels, scene.links, program=program, progress=bar())
    rows = link_budget(scene, args.frame_bytes, limit, channels)
    if rows:
        sizes = f"{args.frame_bytes} bytes" if args.frame_bytes else "the sender's first flow's size, else 64 bytes"
        print(f"\nlink budget (distances at t = 0; frames of {sizes}):")
        print(format_budget(rows[:limit]))
        if limit is not None and len(rows) > limit:
            print("... more pairs not shown (--budget-rows 0 shows them all)")
    if channels is not None:
        from ..sim.water_budget import water_tables

        tables = water_tables(scene, channels, args.frame_bytes, limit)
        if tables:
            print("\nthe water (BELLHOP):")
            print("\n".join(tables))
    print("ok")
    return 0


def _queue_budget(scene) -> str:
    """The POSIX queues and descriptors the scene's GLI endpoints need against this user's limits (a
    warning per limit they exceed; the daemon itself would stop at the first queue it cannot create)."""
    from ..gli.limits import budget_problems, describe, read_limits, scene_need

    from ..gli.limits import queue_names

    limits = read_limits(name for l in scene.links.values() if "mq" in l.gli for name in queue_names(l.id))
    need = scene_need(((l.id, l.gli, l.packet) for l in scene.links.values()), limits)
    lines = [describe(need, limits)]
    lines += [f"warning: the scene exceeds the {problem}" for problem in budget_problems(need, limits)]
    return "\n".join(lines)
