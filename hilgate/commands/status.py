"""``hilgate status``: the running daemon's links and vehicles (``--network``: every host's)."""

from __future__ import annotations

import argparse

from .daemon_client import open_control

NAME = "status"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate status``'s parser, among ``sub``'s."""
    p = sub.add_parser("status", help="show the running daemon's links and vehicles")
    p.add_argument("--json", action="store_true", help='one JSON object: {"links": [...], "vehicles": [...]}')
    p.add_argument("--watch", type=float, metavar="S", help="print again every S seconds")
    p.add_argument("--network", action="store_true",
                   help="every host of the network: its links, and how the others hear it (over Zenoh)")
    p.add_argument("--runtime-dir")
    return p


def run(args: argparse.Namespace) -> int:
    with open_control(args) as control:
        if args.watch:
            control.settimeout(None)
            control.send({"class": "WATCH", "interval_s": args.watch})
            for status in control.replies():
                _print_status(status, args.json)
            return 0
        if args.network:
            _print_network(control.request({"class": "NETWORK"}), args.json)
            return 0
        _print_status(control.request({"class": "STATUS"}), args.json)
    return 0


def _link_note(link: dict) -> str:
    """Why a link is down, else what it lost by cause (the table has one line per link)."""
    if link.get("reason"):
        return link["reason"]
    causes = link.get("drop_causes") or {}
    return ", ".join(f"{cause} {n}" for cause, n in sorted(causes.items()))


def _since(link: dict) -> str:
    """Since when (model time, as ``t`` above) the link has had its backend; counts are over the run."""
    since = link.get("since_s")
    return "-" if since is None else f"{since:.1f}"


def _print_network(answer: dict, as_json: bool) -> None:
    """``hilgate status --network``: every host's daemon, its links and how late the others' frames come."""
    import json

    if answer.get("class") == "ERROR":
        raise OSError(answer.get("error"))
    hosts = answer.get("hosts", [])
    if as_json:
        print(json.dumps(hosts), flush=True)
        return
    from ..report.tables import _render

    rows, seen = [], {}
    for host in hosts:
        for view in host.get("hosts", []):
            seen.setdefault(view["host"], []).append((host["host"], view))
    for host in hosts:
        for link in host.get("links", []):
            rows.append([host["host"], link["id"], link["backend"], link["state"], str(link["tx_packets"]),
                         str(link["rx_packets"]), str(link["drops"]), _link_note(link)])
    print(_render(["host", "link", "backend", "state", "tx", "rx", "drops", "note"], rows))
    print()
    lines = []
    for name, views in sorted(seen.items()):
        for observer, view in views:
            lines.append([name, observer, view["state"], str(view["heard"]), str(view["gaps"]), str(view["late"]),
                          f"{view['late_max_ms']:.3f}",
                          "-" if view["net_delay_mean_ms"] is None else f"{view['net_delay_mean_ms']:.3f}"])
    answered = {host["host"] for host in hosts}
    for name in sorted(set(seen) - answered):
        lines.append([name, "-", "no answer", "", "", "", "", ""])
    print(_render(["host", "seen by", "state", "frames heard", "gaps", "late", "late max ms", "net delay ms"],
                  lines), flush=True)


def _print_status(status: dict, as_json: bool) -> None:
    import json

    if as_json:
        print(json.dumps({"links": status["links"], "vehicles": status["vehicles"],
                          **({"scheduling": status["scheduling"]} if "scheduling" in status else {}),
                          **{key: status[key] for key in ("ros2", "tcp", "web") if key in status}}),
              flush=True)
        return
    _print_links_and_vehicles(status)
    _print_doors(status)
    if status.get("cameras"):
        _print_cameras(status["cameras"])
    if status.get("ros2"):
        _print_ros2(status["ros2"])


def _print_links_and_vehicles(status: dict) -> None:
    from ..report.tables import _render

    print(f"t = {status.get('time', 0):.3f} s")
    if "scheduling" in status:  # (a daemon of an older version does not say)
        print(f"scheduling: {status['scheduling']['text']}")
    print(_render(["link", "backend", "state", "since s", "tx", "rx", "drops", "unread", "fifo B", "note"],
                  [[l["id"], l["backend"], l["state"], _since(l), str(l["tx_packets"]), str(l["rx_packets"]),
                    str(l["drops"]), str(l.get("unread", 0)), str(l["fifo_bytes"]), _link_note(l)]
                   for l in status["links"]], left=3))
    print()
    print(_render(["vehicle", "source", "x", "y", "z", "age s", "pose"],
                  [[v["name"], v["source"], *(f"{c:.3f}" for c in (v["position"] or [float("nan")] * 3)),
                    "-" if v["age_s"] is None else f"{v['age_s']:.2f}", _pose_note(v)] for v in status["vehicles"]]),
          flush=True)


def _refused(counts: dict) -> str:
    return ", ".join(f"{cause} {n}" for cause, n in sorted(counts.items()) if n) or "none"


def _print_doors(status: dict) -> None:
    """The TCP GLI's and the web view's doors: what they refused, who is still to prove the token."""
    tcp = status.get("tcp")
    if tcp:
        print(f"\nTCP GLI: refused {_refused(tcp['refused'])}; {tcp['waiting']} connections waiting to authenticate",
              flush=True)
    web = status.get("web")
    if web and "refused" in web:
        print(f"\nweb view: {web['pages']} pages; refused {_refused(web['refused'])}; {web['waiting']} connections "
              f"waiting to prove the token", flush=True)


def _print_cameras(cameras: list[dict]) -> None:
    from ..report.tables import _render

    print()
    print(_render(["camera", "frames/s", "frames", "problem"],
                  [[c["name"], f"{c['fps']:.1f}", str(c["frames"]), c["error"] or ""] for c in cameras]),
          flush=True)


def _print_ros2(ros2: dict) -> None:
    from ..report.tables import _render

    published = ", ".join(f"{what} {n}" for what, n in ros2.get("published", {}).items() if n) or "nothing"
    print(f"\nROS 2: domain {ros2['domain_id']} on {', '.join(ros2['interfaces'])}, namespace {ros2['namespace']}; "
          f"published {published}" + (f"; {ros2['failed']} writes failed" if ros2.get("failed") else ""), flush=True)
    if ros2["poses_in"]:
        print(_render(["vehicle", "topic", "messages", "applied", "refused"],
                      [[p["vehicle"], p["topic"], str(p["messages"]), str(p["applied"]),
                        ", ".join(f"{cause} {n}" for cause, n in sorted(p["refused"].items())) or "none"]
                       for p in ros2["poses_in"]]), flush=True)


def _pose_note(vehicle: dict) -> str:
    """STALE in capitals: the one word on the table an operator must not miss."""
    stale = vehicle.get("stale")
    return "STALE" if stale == "stale" else "STALE (never heard)" if stale == "never" else "fresh"
