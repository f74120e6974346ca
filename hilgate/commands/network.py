"""``hilgate network init DIR --hosts A,B --apps N``: a lab's credentials (:mod:`.credentials`)."""

from __future__ import annotations

import argparse
import sys

from .options import EXIT_SCENE

NAME = "network"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate network``'s parser, among ``sub``'s."""
    p = sub.add_parser("network", help="a lab's credentials for a network of daemons over Zenoh")
    n = p.add_subparsers(dest="network_command", metavar="ACTION")
    n.required = True
    i = n.add_parser("init", help="a CA and a certificate per host and per application (TLS, access control)")
    i.add_argument("directory", help="where the credentials go (made 0750; keys 0600)")
    i.add_argument("--hosts", required=True, metavar="A,B,...", help="the hosts' names (their daemons' --host)")
    i.add_argument("--apps", default="0", metavar="N|A,B,...",
                   help="applications: a number (app-1 … app-N) or names (default 0)")
    return p


def run(args: argparse.Namespace) -> int:
    """``hilgate network init DIR --hosts A,B --apps N``: the lab's credentials (:mod:`.credentials`)."""
    from .credentials import NetworkInitError, init_network

    hosts = [h.strip() for h in args.hosts.split(",") if h.strip()]
    apps: list[str] | int
    if args.apps.isdigit():
        apps = int(args.apps)
        if apps > 1000:
            print("hilgate: network init: at most 1000 applications", file=sys.stderr)
            return EXIT_SCENE
    else:
        apps = [a.strip() for a in args.apps.split(",") if a.strip()]
    try:
        result = init_network(args.directory, hosts, apps)
    except NetworkInitError as exc:
        print(f"hilgate: network init: {exc}", file=sys.stderr)
        return EXIT_SCENE
    where = args.directory.rstrip("/") or "/"  # as the user wrote it: the paths to copy, in their words
    print(f"credentials in {where}: made {', '.join(result['made']) or 'nothing'}"
          f"{'; kept ' + ', '.join(result['kept']) if result['kept'] else ''}")
    print(f"  hosts: {', '.join(f'{where}/hosts/{h}' for h in result['hosts'])}")
    if result["apps"]:
        print(f"  applications: {where}/apps/{{{','.join(result['apps'])}}}")
    print(f"  keep {where}/ca/ca.key off the lab's computers; copy each host's directory to it and point the "
          f"scene at it (zenoh: {{credentials: DIR}}) or start the daemon with --zenoh-credentials DIR")
    return 0
