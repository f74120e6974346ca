"""``hilgate queues SCENE [--unlink]``: the dccomms POSIX queues of a scene's links."""

from __future__ import annotations

import argparse

from .options import add_scene_args

NAME = "queues"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate queues``'s parser, among ``sub``'s."""
    p = sub.add_parser("queues", help="list (or --unlink) the dccomms POSIX queues of a scene's links")
    add_scene_args(p)
    p.add_argument("--unlink", action="store_true", help="remove them (applications must reopen)")
    return p


def run(args: argparse.Namespace) -> int:
    """dccomms never unlinks its queues, and Linux charges them to their creator until someone does."""
    import posix_ipc

    from ..gli.limits import queue_names
    from ..scene.load import load_scene

    scene = load_scene(args.scene, args.overrides, plugins=args.plugins, preset_dirs=args.preset_dirs)
    for link_id in scene.links:
        for name in queue_names(link_id):
            try:
                queue = posix_ipc.MessageQueue(name)
            except posix_ipc.ExistentialError:
                print(f"{name}: absent")
                continue
            except posix_ipc.Error as exc:
                print(f"{name}: {exc}")
                continue
            line = (f"{name}: {queue.current_messages} waiting, {queue.max_messages} x "
                    f"{queue.max_message_size} bytes")
            queue.close()
            if args.unlink:
                posix_ipc.unlink_message_queue(name)
                line += ", unlinked"
            print(line)
    return 0
