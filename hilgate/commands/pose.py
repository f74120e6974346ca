"""``hilgate pose [VEHICLE…]``: the vehicles' poses, live."""

from __future__ import annotations

import argparse

from ..scene.yaml_nodes import SceneError
from .daemon_client import open_control

NAME = "pose"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate pose``'s parser, among ``sub``'s."""
    p = sub.add_parser("pose", help="follow the vehicles' poses live")
    p.add_argument("vehicle", nargs="*", help="only these vehicles")
    p.add_argument("--interval", type=float, default=0.5, help="seconds between updates (default 0.5)")
    p.add_argument("--runtime-dir")
    return p


def run(args: argparse.Namespace) -> int:
    """Follow the vehicles' poses live, one line per vehicle per update."""
    with open_control(args) as control:
        if args.vehicle:
            known = [v["name"] for v in control.request({"class": "STATUS"}).get("vehicles", [])]
            for name in args.vehicle:
                if name not in known:
                    raise SceneError("pose", 0, "", _unknown_vehicle(name, known))
        control.settimeout(None)
        control.send({"class": "WATCH", "interval_s": args.interval})
        for status in control.replies():
            for v in status.get("vehicles", []):
                if args.vehicle and v["name"] not in args.vehicle:
                    continue
                position = v["position"]
                where = "no pose" if position is None else "  ".join(f"{c:8.3f}" for c in position)
                age = "-" if v["age_s"] is None else f"{v['age_s']:.2f} s old"
                print(f"{status.get('time', 0):10.3f}  {v['name']:<12} {where}  {v['source']} {age}", flush=True)
    return 0


def _unknown_vehicle(name: str, known: list[str]) -> str:
    import difflib

    close = difflib.get_close_matches(name, known, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"no vehicle {name!r} in the running scene{hint}; its vehicles: {', '.join(known) or 'none'}"
