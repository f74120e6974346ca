"""``hilgate emulate PROTOCOL [SCENE] --link ID``: the daemon on a scene, with one of its simulated links shown
as a modem device."""

from __future__ import annotations

import argparse

from ..scene.yaml_nodes import SceneError
from . import run as run_command
from .options import add_scene_args

NAME = "emulate"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate emulate``'s parser, among ``sub``'s: its own options, then the daemon's (not its --tcp)."""
    e = sub.add_parser("emulate", help="run a scene with one simulated link shown as a modem device "
                                       "(EvoLogics, S100, Modem-M64, Micro-Modem)")
    e.add_argument("protocol", choices=emulated_protocols())
    add_scene_args(e, optional=True)
    e.add_argument("--link", required=True, help="the simulated link to expose")
    e.add_argument("--pty", help="link the emulated device's pseudo-terminal here (e.g. /tmp/ttyEVO0)")
    e.add_argument("--tcp", type=int, help="listen on this loopback port instead (EvoLogics only)")
    e.add_argument("--baud", type=int, help="the serial line the emulated S100 paces itself at (default 9600)")
    e.add_argument("--rtscts", action=argparse.BooleanOptionalAction, default=None,
                   help="the emulated S100 has RTS/CTS flow control (default: without, 45 bytes at a time)")
    daemon = argparse.ArgumentParser(add_help=False)
    run_command.add_daemon_options(daemon)
    for action in daemon._actions:  # the daemon's own options (speed, runtime dir, trace…), not its --tcp
        if action.dest != "tcp":
            e._add_action(action)
    return e


def run(args: argparse.Namespace) -> int:
    """The daemon on a scene, with one of its simulated links shown as a modem device."""
    import json

    where = {"pty": args.pty} if args.pty else {"tcp": args.tcp}
    if not args.pty and args.tcp is None:
        raise SceneError("hilgate emulate", 0, "", "give --pty PATH or --tcp PORT")
    line = {key: value for key, value in (("baud", args.baud), ("rtscts", args.rtscts)) if value is not None}
    emulate = {"protocol": args.protocol, **where, **line}  # the scene checks the line options (S100 only)
    from ..core.paths import default_scene

    args.scene = args.scene or default_scene()
    _emulated_link_exists(args.scene, args.link, args.overrides)
    args.overrides = [*args.overrides, f"links.{args.link}.emulate={json.dumps(emulate)}"]
    args.tcp = None  # here --tcp is the emulated modem's port, not a GLI listener
    return run_command.run(args)


def _emulated_link_exists(scene_path: str, link: str, overrides: list[str]) -> None:
    """``--link`` names a link of the scene (or of a ``--set``): said as such, with the scene's links, not as
    the ``--set`` that ``emulate`` makes of it ("links.X: missing required key 'vehicle'")."""
    import difflib

    import yaml

    try:
        with open(scene_path, encoding="utf-8") as file:
            data = yaml.safe_load(file)
    except (OSError, yaml.YAMLError):
        return  # the scene's own loading says what is wrong with the file
    links = list((data or {}).get("links") or {}) if isinstance(data, dict) else []
    if link in links or any(o.startswith(f"links.{link}.") or o.startswith(f"links.{link}=") for o in overrides):
        return
    close = difflib.get_close_matches(link, links, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise SceneError("--link", 0, "", f"no link {link!r} in {scene_path}{hint}; its links: "
                                      f"{', '.join(links) or 'none'}")


def emulated_protocols() -> list[str]:
    from ..drivers.table import emulated_protocols as protocols

    return list(protocols())
