"""``hilgate send LINK [TEXT…]``: text to a link, each frame confirmed or reported refused."""

from __future__ import annotations

import argparse
import sys

from .daemon_client import open_link
from .options import TOKEN_HELP, add_zenoh_args, address, tcp_address

NAME = "send"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate send``'s parser, among ``sub``'s."""
    p = sub.add_parser("send", help="send text to a link (arguments, or one frame per stdin line)")
    p.add_argument("link")
    p.add_argument("text", nargs="*")
    p.add_argument("--to", type=address, default=255, help="destination address (default 255, broadcast)")
    p.add_argument("--tcp", metavar="[HOST:]PORT", type=tcp_address)
    p.add_argument("--token-file", metavar="FILE", help=TOKEN_HELP)
    add_zenoh_args(p)
    p.add_argument("--runtime-dir")
    return p


def run(args: argparse.Namespace) -> int:
    """Each frame is followed by a round trip to the daemon: an ERROR it answered the frame with
    arrives first, so a refused frame is reported (and the exit status is 1), not lost silently.
    A frame it took is confirmed in one line, with its destination as the channel model reads it
    (on a link whose packet class carries no address on air and that has no MAC, a frame reaches
    every modem in range whatever its destination: UWSim-NET's behaviour, ``addressing: auto``)."""
    from ..gli.socket_client import GliError

    refused = 0
    with open_link(args) as link:
        frames = [" ".join(args.text)] if args.text else (line.rstrip("\n") for line in sys.stdin)
        for number, text in enumerate(frames, 1):
            data = text.encode()
            link.send(data, args.to)
            try:
                answer = link.command({"class": "STATUS"})
            except GliError as exc:
                refused += 1
                print(f"hilgate: {link.id}: frame {number} refused: {exc}", file=sys.stderr)
                continue
            print(f"{link.id}: frame {number} sent, {len(data)} bytes to {_destination(args.to, answer)}", flush=True)
    return 1 if refused else 0


def _destination(dst: int, answer: dict) -> str:
    """Where a frame sent to ``dst`` goes, as the model reads it (the daemon's STATUS of the link says)."""
    if dst == 255:
        return "255 (broadcast)"
    reach = (answer.get("link") or {}).get("app_dst")
    if reach == "everyone in range":
        return (f"{dst}, which reaches everyone in range (addressing: auto, and the link's packet class "
                f"carries no address on air)")
    return str(dst)
