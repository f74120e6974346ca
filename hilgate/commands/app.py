"""``hilgate app MODULE:CLASS --link ID …``: an application as a process against a running daemon."""

from __future__ import annotations

import argparse
import sys

from ..scene.yaml_nodes import SceneError
from .daemon_client import zenoh_option
from .options import TOKEN_HELP, add_zenoh_args, tcp_address

NAME = "app"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate app``'s parser, among ``sub``'s."""
    p = sub.add_parser("app", help="run an application (hilgate.app.Application) against a running daemon")
    p.add_argument("application", metavar="MODULE:CLASS", help="a module name or a .py file, and the class")
    p.add_argument("--link", dest="links", action="append", required=True, metavar="ID",
                   help="a link the application uses (repeatable; ctx.links in this order)")
    p.add_argument("--param", dest="params", action="append", default=[], metavar="KEY=VALUE",
                   help="ctx.params[KEY] (VALUE read as YAML: 10, 0.5, true, [1, 2], text)")
    p.add_argument("--name", help="the application's name (default: the class name; seeds ctx.random)")
    p.add_argument("--seed", type=int, help="seed of ctx.random (default: not reproducible)")
    p.add_argument("--until", type=float, metavar="S", help="stop after S seconds (default: SIGTERM/SIGINT)")
    p.add_argument("--tcp", metavar="[HOST:]PORT", type=tcp_address, help="the daemon's TCP GLI listener")
    p.add_argument("--token-file", metavar="FILE", help=TOKEN_HELP)
    add_zenoh_args(p)
    p.add_argument("--runtime-dir")
    return p


def run(args: argparse.Namespace) -> int:
    """``hilgate app MODULE:CLASS --link ID …``: the application as a process against a running daemon."""
    import os

    from ..core.application import Application
    from ..daemon.service import parse_tcp
    from ..gli.app_runner import run_application
    from ..scene.plugins import PluginError, load_plugin
    from ..scene.yaml_nodes import parse_value

    entry, colon, class_name = args.application.rpartition(":")
    if not colon or not entry or not class_name.isidentifier():
        raise SceneError(args.application, 0, "", "give the application as MODULE:CLASS or FILE.py:CLASS")
    try:
        plugin = load_plugin(entry, os.getcwd())
    except PluginError as exc:
        raise SceneError(entry, 0, "", f"cannot load the application's module: {exc}") from None
    cls = getattr(plugin.module, class_name, None)  # (by name: the class the scene names, by its name)
    if not (isinstance(cls, type) and issubclass(cls, Application)):
        raise SceneError(entry, 0, "", f"{class_name!r} is not an application (a subclass of hilgate.app.Application)")
    params = {}
    for item in args.params:
        key, equals, value = item.partition("=")
        if not equals or not key.isidentifier():
            raise SceneError("--param", 0, "", f"{item[:60]!r} is not KEY=VALUE")
        # read as a scene's values are, within the same limits: 20 000 nested brackets or a number of
        # 100 000 digits is one line (not a RecursionError after 16 s, nor a ValueError)
        params[key] = parse_value(value, f"--param {key}") if value else ""
    return run_application(cls, args.links, params, name=args.name, seed=args.seed, runtime_dir=args.runtime_dir,
                           tcp=parse_tcp(args.tcp) if args.tcp else None, zenoh=zenoh_option(args), until=args.until,
                           token_file=args.token_file, report=lambda line: print(line, file=sys.stderr, flush=True))
