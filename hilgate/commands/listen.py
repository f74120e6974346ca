"""``hilgate listen LINK``: what a link receives, one line a frame."""

from __future__ import annotations

import argparse
import sys

from .daemon_client import open_link
from .options import TOKEN_HELP, add_zenoh_args, tcp_address

NAME = "listen"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate listen``'s parser, among ``sub``'s."""
    p = sub.add_parser("listen", help="print what a link receives")
    p.add_argument("link")
    p.add_argument("--count", type=int, help="stop after N frames")
    p.add_argument("--timeout", type=float, help="stop after S seconds without a frame")
    p.add_argument("--hex", action="store_true", help="print payloads in hex")
    p.add_argument("--tcp", metavar="[HOST:]PORT", type=tcp_address)
    p.add_argument("--token-file", metavar="FILE", help=TOKEN_HELP)
    add_zenoh_args(p)
    p.add_argument("--runtime-dir")
    return p


def run(args: argparse.Namespace) -> int:
    count = 0
    with open_link(args) as link:
        print(f"listening on {link.id} (address {link.address}, {link.info['packet']})", file=sys.stderr, flush=True)
        while args.count is None or count < args.count:
            message = link.recv(timeout=args.timeout)
            if message is None:
                break
            count += 1
            text = message.data.decode("utf-8", "backslashreplace") if not args.hex else message.data.hex()
            print(f"{message.t:.6f} {message.src} -> {message.dst}: {text}", flush=True)
    return 0
