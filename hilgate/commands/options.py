"""Options and argument types that several commands share (a scene and its overrides, addresses, Zenoh
endpoints): each checked where argparse reads it, so a wrong value is a one-line usage error."""

from __future__ import annotations

import argparse



EXIT_SCENE = 2
TOKEN_HELP = ("with --tcp: the daemon's TCP GLI token (default $HILGATE_TCP_TOKEN_FILE, else the local daemon's "
              "RUNTIME/tcp.token)")


def add_scene_args(parser: argparse.ArgumentParser, optional: bool = False) -> None:
    if optional:
        parser.add_argument("scene", nargs="?", help="scene file (YAML)")
    else:
        parser.add_argument("scene", help="scene file (YAML)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                        help="override a scene value, '*' matches every key at its level "
                             "(e.g. --set 'links.*.mac.protocol=s-fama'); VALUE null removes the key; repeatable")
    parser.add_argument("--plugin", dest="plugins", action="append", default=[], metavar="FILE.py|MODULE",
                        help="load this plugin (e.g. a MAC protocol) besides the scene's plugins: list; a .py file "
                             "(relative to the working directory) or an installed module; repeatable")
    parser.add_argument("--preset-dir", dest="preset_dirs", action="append", default=[], metavar="DIR",
                        help="model: preset files may also come from this directory (besides the scene's own); "
                             "repeatable")


def address(value: str) -> int:
    try:
        address = int(value, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not an address (0..255, 255 broadcasts)") from None
    if not 0 <= address <= 255:
        raise argparse.ArgumentTypeError(f"{address} is not an address (0..255, 255 broadcasts)")
    return address


def zenoh_prefix(value: str) -> str:
    from ..core.names import zenoh_prefix_problem

    if zenoh_prefix_problem(value):
        raise argparse.ArgumentTypeError(f"{value[:60]!r}: {zenoh_prefix_problem(value)}")
    return value


def add_zenoh_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--zenoh", action="append", metavar="ENDPOINT", type=zenoh_endpoint,
                        help="reach the link over Zenoh through this daemon endpoint, e.g. tcp/192.168.1.10:7447 "
                             "(repeatable)")
    parser.add_argument("--zenoh-prefix", type=zenoh_prefix, metavar="PREFIX",
                        help="the network's Zenoh key prefix, as its scene's zenoh: prefix: (default: hilgate)")
    parser.add_argument("--zenoh-credentials", metavar="DIR",
                        help="this application's credentials on an authenticated network (hilgate network init: "
                             "DIR/apps/NAME)")


def tcp_address(value: str) -> str:
    from ..daemon.service import parse_tcp

    return parsed_by(parse_tcp, value)


def web_address(value: str) -> str:
    from ..web.server import parse_web

    return parsed_by(parse_web, value)


def handshake_seconds(value: str) -> float:
    try:
        seconds = float(value)
    except ValueError:
        seconds = float("nan")
    if not 0.1 <= seconds <= 3600:
        raise argparse.ArgumentTypeError(f"{value!r} is not a number of seconds from 0.1 to 3600")
    return seconds


def parsed_by(parse, value: str) -> str:
    """``value`` as it was given, once ``parse`` took it (the parser is imported by the option's own check, so
    that ``hilgate`` starts without it); its ValueError is argparse's one-line usage error."""
    try:
        parse(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value


def zenoh_endpoint(value: str) -> str:
    """``--zenoh``/``--zenoh-connect``/``--zenoh-listen``: checked as a scene's ``zenoh.connect`` is, so
    ``'{"a":'`` is a usage error here rather than a zenoh.ZError from inside the session."""
    from ..scene.hosts import ENDPOINT

    if not ENDPOINT.fullmatch(value):
        raise argparse.ArgumentTypeError(f"{value[:60]!r} is not a Zenoh endpoint like tcp/192.168.1.10:7447")
    return value
