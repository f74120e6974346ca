"""How a command reaches the running daemon: its control socket (status, reload, pose, view) or a link's GLI,
over the local socket, TCP or Zenoh (send, listen, app)."""

from __future__ import annotations

import argparse

from ..scene.yaml_nodes import SceneError



def open_control(args: argparse.Namespace):
    from ..control_client import Control

    return Control(args.runtime_dir)


def control_request(args: argparse.Namespace, request_obj: dict) -> dict:
    with open_control(args) as control:
        return control.request(request_obj)


def zenoh_option(args: argparse.Namespace):
    """``--zenoh ENDPOINT`` (repeatable) and ``--zenoh-prefix`` as the client's ``zenoh=``; None without."""
    if not args.zenoh:
        if args.zenoh_prefix:
            raise SceneError("--zenoh-prefix", 0, "", "names the key prefix of a Zenoh network: give --zenoh "
                                                      "ENDPOINT too (a daemon of that network)")
        return None
    if args.tcp:
        raise SceneError("--zenoh", 0, "", "give --tcp or --zenoh, not both")
    return {"connect": args.zenoh, **({"prefix": args.zenoh_prefix} if args.zenoh_prefix else {}),
            **({"credentials": args.zenoh_credentials} if args.zenoh_credentials else {})}


def open_link(args: argparse.Namespace):
    from ..gli.socket_client import Link
    from ..daemon.service import parse_tcp

    return Link.open(args.link, tcp=parse_tcp(args.tcp) if args.tcp else None, runtime_dir=args.runtime_dir,
                     token_file=args.token_file, zenoh=zenoh_option(args))
