"""The ``hilgate`` command: check, sim, run, status, send, listen, emulate, report."""

from __future__ import annotations

import argparse
import logging
import math
import sys
from typing import Callable

from . import __version__
from .scene.yaml_nodes import SceneError

log = logging.getLogger(__name__)

EXIT_SCENE = 2
TOKEN_HELP = ("with --tcp: the daemon's TCP GLI token (default $HILGATE_TCP_TOKEN_FILE, else the local daemon's "
              "RUNTIME/tcp.token)")


def _add_scene_args(parser: argparse.ArgumentParser, optional: bool = False) -> None:
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


def cmd_check(args: argparse.Namespace) -> int:
    from .scene.load import load_scene, scene_summary

    from .sim.budget import format_budget, link_budget

    scene = load_scene(args.scene, args.overrides, plugins=args.plugins, preset_dirs=args.preset_dirs)
    print(scene_summary(scene))
    print(_queue_budget(scene))
    limit = None if args.budget_rows == 0 else args.budget_rows
    channels = None
    if any(channel.water is not None for channel in scene.channels.values()):
        from .channel.prepare import ready_channels
        from .channel.runner import bar, find_program

        program = find_program(args.bellhop) if args.bellhop else None
        channels = ready_channels(scene.channels, scene.links, program=program, progress=bar())
    rows = link_budget(scene, args.frame_bytes, limit, channels)
    if rows:
        sizes = f"{args.frame_bytes} bytes" if args.frame_bytes else "the sender's first flow's size, else 64 bytes"
        print(f"\nlink budget (distances at t = 0; frames of {sizes}):")
        print(format_budget(rows[:limit]))
        if limit is not None and len(rows) > limit:
            print("... more pairs not shown (--budget-rows 0 shows them all)")
    if channels is not None:
        from .sim.water_budget import water_tables

        tables = water_tables(scene, channels, args.frame_bytes, limit)
        if tables:
            print("\nthe water (BELLHOP):")
            print("\n".join(tables))
    print("ok")
    return 0


def cmd_channel(args: argparse.Namespace) -> int:
    """``hilgate channel prepare SCENE``: BELLHOP's fields of every channel with water, into the cache."""
    from .channel.prepare import frequencies_of, ready_channels
    from .channel.runner import bar, cache_dir, find_program
    from .scene.load import load_scene

    scene = load_scene(args.scene, args.overrides, plugins=args.plugins, preset_dirs=args.preset_dirs)
    watery = {name: c for name, c in scene.channels.items() if c.water is not None}
    if not watery:
        print(f"{args.scene}: no channel has water: nothing to prepare")
        return 0
    program = find_program(args.bellhop) if args.bellhop else None
    ready = ready_channels(watery, scene.links, program=program, progress=bar())
    for name, channel in watery.items():
        hz = ", ".join(f"{f / 1000:g}" for f in sorted(frequencies_of(channel, scene.links)))
        fans = "; ".join(_fan_line(fields) for fields in ready[name].propagation.fields)
        print(f"channel {name}: BELLHOP fields at {hz} kHz ready in {cache_dir()} ({fans})")
    return 0


def _fan_line(fields) -> str:
    """How many beams a field was traced with, and how converged (``hilgate/channel/beams.py``)."""
    khz = f"{fields.frequency_hz / 1000:g} kHz"
    if fields.fan is None:
        return khz
    beams, change, largest = fields.fan
    if math.isnan(change):  # the scene gave the fan
        return f"{khz}: {beams} beams as given" if beams else f"{khz}: as many beams as BELLHOP chose"
    return (f"{khz}: {beams} beams; doubling to them moved the TL by {change:.2f} dB or less at 99.9 % of the "
            f"grid, {largest:.2f} dB at most")


def _queue_budget(scene) -> str:
    """The POSIX queues and descriptors the scene's GLI endpoints need against this user's limits (a
    warning per limit they exceed; the daemon itself would stop at the first queue it cannot create)."""
    from .gli.limits import budget_problems, describe, read_limits, scene_need

    from .gli.limits import queue_names

    limits = read_limits(name for l in scene.links.values() if "mq" in l.gli for name in queue_names(l.id))
    need = scene_need(((l.id, l.gli, l.packet) for l in scene.links.values()), limits)
    lines = [describe(need, limits)]
    lines += [f"warning: the scene exceeds the {problem}" for problem in budget_problems(need, limits)]
    return "\n".join(lines)


def cmd_sim(args: argparse.Namespace) -> int:
    from .core.outputs import OutputError, open_output, output_problem
    from .scene.load import load_scene
    from .sim.simulate import simulate, write_summary
    from .report.tables import format_summary

    scene = load_scene(args.scene, args.overrides, plugins=args.plugins, preset_dirs=args.preset_dirs)
    if args.until is not None and args.until <= 0:
        raise SceneError("--until", 0, "", f"must be positive, not {args.until:g}")
    trace_path = args.trace if args.trace is not None else scene.trace_file
    if args.summary:  # refused before the run, not after it
        problem = output_problem(args.summary, "summary")
        if problem is not None:
            raise OutputError(problem)
    trace = open_output(trace_path, "trace", append=False, buffering=1 << 20) if trace_path else None
    try:
        progress = sys.stderr.isatty() and not args.quiet
        summary = simulate(scene, until=args.until, seed=args.seed, trace=trace, progress=progress)
    finally:
        if trace is not None:
            trace.close()
    if args.summary:
        write_summary(summary, args.summary)
    if not args.quiet:
        print(format_summary(summary))
        if trace_path:
            print(f"\ntrace: {trace_path}")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from .daemon.service import Daemon
    from .core.paths import daemon_runtime_dir, default_scene
    from .core.priority import DEFAULT_PRIORITY

    scene = args.scene or default_scene()
    if args.speed <= 0:
        raise SceneError("--speed", 0, "", f"must be positive, not {args.speed:g}")
    status_line = args.status_line if args.status_line is not None else sys.stderr.isatty()
    if args.realtime_priority is not None and not 1 <= args.realtime_priority <= 99:
        raise SceneError("--realtime-priority", 0, "", f"must be from 1 to 99, not {args.realtime_priority}")
    realtime = args.realtime_priority or (DEFAULT_PRIORITY if args.realtime else 0)
    daemon = Daemon(scene, args.overrides, daemon_runtime_dir(args.runtime_dir), args.speed, args.tcp,
                    args.trace, args.summary, args.until, status_line, args.gli_backlog, args.group,
                    args.max_clients, args.max_link_clients, plugins=args.plugins, preset_dirs=args.preset_dirs,
                    host=args.host, zenoh_connect=args.zenoh_connect, zenoh_listen=args.zenoh_listen,
                    clock_offset_s=args.clock_offset_s, tcp_token=args.tcp_token,
                    zenoh_credentials=args.zenoh_credentials, zenoh_insecure=args.zenoh_insecure, web=args.web,
                    auth_timeout_s=args.auth_timeout, realtime_priority=realtime)
    return daemon.run()


def _control(args: argparse.Namespace):
    from .control_client import Control

    return Control(args.runtime_dir)


def cmd_status(args: argparse.Namespace) -> int:
    with _control(args) as control:
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


def cmd_reload(args: argparse.Namespace) -> int:
    """SIGHUP without knowing the daemon's PID: the RELOAD request, answered once the scene file is
    applied or refused (the daemon then keeps the scene it had)."""
    with _control(args) as control:
        control.settimeout(args.timeout)
        answer = control.request({"class": "RELOAD"})
    if not answer.get("ok"):
        print(f"hilgate: reload refused, the daemon keeps its scene: {answer.get('error')}", file=sys.stderr)
        return EXIT_SCENE
    links = _control_request(args, {"class": "STATUS"}).get("links", [])
    listed = ", ".join(f"{link['id']}={link['backend']}" for link in links)
    print(f"reloaded: {len(links)} links ({listed})")
    return 0


def _control_request(args: argparse.Namespace, request_obj: dict) -> dict:
    with _control(args) as control:
        return control.request(request_obj)


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
    from .report.tables import _render

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
    from .report.tables import _render

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
    tcp = status.get("tcp")
    if tcp:
        refused = ", ".join(f"{cause} {n}" for cause, n in sorted(tcp["refused"].items()) if n) or "none"
        print(f"\nTCP GLI: refused {refused}; {tcp['waiting']} connections waiting to authenticate", flush=True)
    web = status.get("web")
    if web and "refused" in web:
        refused = ", ".join(f"{cause} {n}" for cause, n in sorted(web["refused"].items()) if n) or "none"
        print(f"\nweb view: {web['pages']} pages; refused {refused}; {web['waiting']} connections waiting to "
              f"prove the token", flush=True)
    if status.get("cameras"):
        print()
        print(_render(["camera", "frames/s", "frames", "problem"],
                      [[c["name"], f"{c['fps']:.1f}", str(c["frames"]), c["error"] or ""] for c in status["cameras"]]),
              flush=True)
    ros2 = status.get("ros2")
    if ros2:
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


def cmd_pose(args: argparse.Namespace) -> int:
    """Follow the vehicles' poses live, one line per vehicle per update."""
    with _control(args) as control:
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


def _zenoh_option(args: argparse.Namespace):
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


def _open_link(args: argparse.Namespace):
    from .gli.socket_client import Link
    from .daemon.service import parse_tcp

    return Link.open(args.link, tcp=parse_tcp(args.tcp) if args.tcp else None, runtime_dir=args.runtime_dir,
                     token_file=args.token_file, zenoh=_zenoh_option(args))


def cmd_send(args: argparse.Namespace) -> int:
    """Each frame is followed by a round trip to the daemon: an ERROR it answered the frame with
    arrives first, so a refused frame is reported (and the exit status is 1), not lost silently.
    A frame it took is confirmed in one line, with its destination as the channel model reads it
    (on a link whose packet class carries no address on air and that has no MAC, a frame reaches
    every modem in range whatever its destination: UWSim-NET's behaviour, ``addressing: auto``)."""
    from .gli.socket_client import GliError

    refused = 0
    with _open_link(args) as link:
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


def cmd_app(args: argparse.Namespace) -> int:
    """``hilgate app MODULE:CLASS --link ID …``: the application as a process against a running daemon."""
    import os

    from .core.application import Application
    from .daemon.service import parse_tcp
    from .gli.app_runner import run_application
    from .scene.plugins import PluginError, load_plugin
    from .scene.yaml_nodes import parse_value

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
                           tcp=parse_tcp(args.tcp) if args.tcp else None, zenoh=_zenoh_option(args), until=args.until,
                           token_file=args.token_file, report=lambda line: print(line, file=sys.stderr, flush=True))


def _address(value: str) -> int:
    try:
        address = int(value, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not an address (0..255, 255 broadcasts)") from None
    if not 0 <= address <= 255:
        raise argparse.ArgumentTypeError(f"{address} is not an address (0..255, 255 broadcasts)")
    return address


def _zenoh_prefix(value: str) -> str:
    from .core.names import zenoh_prefix_problem

    if zenoh_prefix_problem(value):
        raise argparse.ArgumentTypeError(f"{value[:60]!r}: {zenoh_prefix_problem(value)}")
    return value


def _add_zenoh_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--zenoh", action="append", metavar="ENDPOINT", type=_zenoh_endpoint,
                        help="reach the link over Zenoh through this daemon endpoint, e.g. tcp/192.168.1.10:7447 "
                             "(repeatable)")
    parser.add_argument("--zenoh-prefix", type=_zenoh_prefix, metavar="PREFIX",
                        help="the network's Zenoh key prefix, as its scene's zenoh: prefix: (default: hilgate)")
    parser.add_argument("--zenoh-credentials", metavar="DIR",
                        help="this application's credentials on an authenticated network (hilgate network init: "
                             "DIR/apps/NAME)")


def _tcp_address(value: str) -> str:
    from .daemon.service import parse_tcp

    return _parsed_by(parse_tcp, value)


def _web_address(value: str) -> str:
    from .web.server import parse_web

    return _parsed_by(parse_web, value)


def _handshake_seconds(value: str) -> float:
    try:
        seconds = float(value)
    except ValueError:
        seconds = float("nan")
    if not 0.1 <= seconds <= 3600:
        raise argparse.ArgumentTypeError(f"{value!r} is not a number of seconds from 0.1 to 3600")
    return seconds


def _parsed_by(parse, value: str) -> str:
    """``value`` as it was given, once ``parse`` took it (the parser is imported by the option's own check, so
    that ``hilgate`` starts without it); its ValueError is argparse's one-line usage error."""
    try:
        parse(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value


def cmd_view(args: argparse.Namespace) -> int:
    from .viewcmd import live_address, serve_trace

    if args.trace is None:
        return live_address(args, lambda request: _control_request(args, request))
    return serve_trace(args)


def _zenoh_endpoint(value: str) -> str:
    """``--zenoh``/``--zenoh-connect``/``--zenoh-listen``: checked as a scene's ``zenoh.connect`` is, so
    ``'{"a":'`` is a usage error here rather than a zenoh.ZError from inside the session."""
    from .scene.hosts import ENDPOINT

    if not ENDPOINT.fullmatch(value):
        raise argparse.ArgumentTypeError(f"{value[:60]!r} is not a Zenoh endpoint like tcp/192.168.1.10:7447")
    return value


def cmd_listen(args: argparse.Namespace) -> int:
    count = 0
    with _open_link(args) as link:
        print(f"listening on {link.id} (address {link.address}, {link.info['packet']})", file=sys.stderr, flush=True)
        while args.count is None or count < args.count:
            message = link.recv(timeout=args.timeout)
            if message is None:
                break
            count += 1
            text = message.data.decode("utf-8", "backslashreplace") if not args.hex else message.data.hex()
            print(f"{message.t:.6f} {message.src} -> {message.dst}: {text}", flush=True)
    return 0


def cmd_queues(args: argparse.Namespace) -> int:
    """dccomms never unlinks its queues, and Linux charges them to their creator until someone does."""
    import posix_ipc

    from .gli.limits import queue_names
    from .scene.load import load_scene

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


def cmd_emulate(args: argparse.Namespace) -> int:
    """The daemon on a scene, with one of its simulated links shown as a modem device."""
    import json

    where = {"pty": args.pty} if args.pty else {"tcp": args.tcp}
    if not args.pty and args.tcp is None:
        raise SceneError("hilgate emulate", 0, "", "give --pty PATH or --tcp PORT")
    line = {key: value for key, value in (("baud", args.baud), ("rtscts", args.rtscts)) if value is not None}
    emulate = {"protocol": args.protocol, **where, **line}  # the scene checks the line options (S100 only)
    from .core.paths import default_scene

    args.scene = args.scene or default_scene()
    _emulated_link_exists(args.scene, args.link, args.overrides)
    args.overrides = [*args.overrides, f"links.{args.link}.emulate={json.dumps(emulate)}"]
    args.tcp = None  # here --tcp is the emulated modem's port, not a GLI listener
    return cmd_run(args)


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


def cmd_report(args: argparse.Namespace) -> int:
    from .report.figures import DPI, report
    from .report.tracedata import pick_run, trace_runs
    from .report.tracefile import TraceError

    try:
        runs = trace_runs(args.trace)
        run = pick_run(runs, args.run)
        if len(runs) > 1:
            which = "the last" if args.run is None else f"number {run.index}"
            print(f"{args.trace} holds {len(runs)} runs of the daemon; showing {which}: run {run.id} started "
                  f"{run.start} (scene {run.scene}); choose another with --run ID or --run N", file=sys.stderr)
        formats = tuple(dict.fromkeys(["png", *(args.formats or [])]))
        dpi = DPI if args.dpi is None else args.dpi
        written = report(args.trace, args.summaries, args.out, args.vehicles, args.csv, args.title,
                         tuple(args.window) if args.window else None, run if len(runs) > 1 else None, formats,
                         args.width, dpi, args.captions)
        if args.water:
            from .waterfig import water_figures

            drawn = water_figures(args.trace, args.water, args.out, formats, dpi)
            if not drawn:
                print(f"{args.water}: no channel with water, or no simulated sender with a pose in the trace: "
                      f"no field drawn", file=sys.stderr)
            written = drawn + written
    except TraceError as exc:  # (ReportError is one): a line that names the file, the line and what is wrong
        print(f"hilgate: {exc}", file=sys.stderr)
        return 1
    print(f"{len(written)} files in {args.out}: open {written[-1]}")
    return 0


def cmd_fit(args: argparse.Namespace) -> int:
    from .fitcmd import plot_fit, print_fit, run_fit
    from .report.tracefile import TraceError

    import numpy as np

    try:
        with np.errstate(all="ignore"):  # degenerate data give infinite intervals, printed as such
            result = run_fit(args.trace, args.scene, args.model, args.link, args.simulated, args.run, args.pose_gap,
                             args.window, tuple(args.overrides))
            print_fit(result, sys.stdout, args.bins)
        if args.plot:
            plot_fit(result, args.plot, args.bins)
            print(f"\nplot: {args.plot}")
    except TraceError as exc:  # (FitError is one)
        print(f"hilgate: fit: {exc}", file=sys.stderr)
        return EXIT_SCENE
    return 0


def cmd_network(args: argparse.Namespace) -> int:
    """``hilgate network init DIR --hosts A,B --apps N``: the lab's credentials (:mod:`hilgate.netinit`)."""
    from .netinit import NetworkInitError, init_network

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


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "network": cmd_network,
    "report": cmd_report,
    "view": cmd_view,
    "fit": cmd_fit,
    "emulate": cmd_emulate,
    "queues": cmd_queues,
    "check": cmd_check,
    "channel": cmd_channel,
    "sim": cmd_sim,
    "run": cmd_run,
    "status": cmd_status,
    "reload": cmd_reload,
    "pose": lambda args: cmd_pose(args),
    "send": cmd_send,
    "listen": cmd_listen,
    "app": cmd_app,
}


def emulated_protocols() -> list[str]:
    from .drivers.table import emulated_protocols as protocols

    return list(protocols())


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hilgate",
        description="Hardware-in-the-loop gateway for underwater communications: dccomms GLI links routed "
                    "to real modems or to a simulated channel.",
    )
    parser.add_argument("--version", action="version", version=f"hilgate {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser("check", help="validate a scene file and print what it contains and what its error "
                                      "models mean (SNR, PER now, where PER crosses 0.1 and 0.9)")
    _add_scene_args(p)
    p.add_argument("--frame-bytes", type=int, metavar="N",
                   help="PER of frames of N bytes (default: the size of the sender's first flow, else 64)")
    p.add_argument("--budget-rows", type=int, default=50, metavar="N",
                   help="show at most N pairs in the link budget (default 50; 0: all)")
    p.add_argument("--bellhop", metavar="COMMAND", help="the BELLHOP program for channels with water (default: "
                   "HILGATE_BELLHOP, bellhop.exe on the PATH, or the checkout's .venv-bellhop)")

    p = sub.add_parser("channel", help="channels that know the water: 'prepare' computes BELLHOP's fields of a "
                                        "scene's channels with water into the cache (with a progress bar)")
    p.add_argument("action", choices=("prepare",))
    _add_scene_args(p)
    p.add_argument("--bellhop", metavar="COMMAND", help="the BELLHOP program (default: HILGATE_BELLHOP, "
                   "bellhop.exe on the PATH, or the checkout's .venv-bellhop)")

    p = sub.add_parser("fit", help="fit an error: block (loss against distance) to the frames of a trace")
    p.add_argument("trace", help="a trace (JSON lines) of hilgate run with real links, or of hilgate sim with "
                                 "--simulated")
    p.add_argument("--scene", help="the scene of the run (default: the one the trace's run line names)")
    p.add_argument("--link", action="append", metavar="ID",
                   help="fit the frames these links received (default: every receiver); repeatable")
    p.add_argument("--model", choices=("power", "logistic", "physical"), default="power",
                   help="power: BER = a*d^b per bit (default); logistic in d; physical: effective source level "
                        "and spreading k of the receivers' error: {kind: physical}")
    p.add_argument("--simulated", action="store_true",
                   help="the trace is of a simulated run: fit its simulated links' frames")
    p.add_argument("--run", help="which run of a daemon's trace (id or number; default: the last)")
    p.add_argument("--pose-gap", type=float, default=2.0, metavar="S",
                   help="leave out frames with no pose sample within S seconds (default 2)")
    p.add_argument("--window", type=float, default=5.0, metavar="S",
                   help="real links: a frame counts as received when the receiver traced it within S seconds")
    p.add_argument("--bins", type=int, default=10, help="distance bins in the table and plot (default 10)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the fit, its band and the binned data (matplotlib)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a value of the scene, as for check and sim")

    p = sub.add_parser("sim", help="run a scene in virtual time, as fast as possible")
    _add_scene_args(p)
    p.add_argument("--until", type=float, help="simulated seconds (default: the scene's duration_s)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's seed)")
    p.add_argument("--trace", help="write the event trace (JSON lines) here")
    p.add_argument("--summary", help="write the summary (JSON) here")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing at the end")

    p = sub.add_parser("run", help="the daemon: GLI endpoints for every link, in real time")
    _add_scene_args(p, optional=True)
    p.add_argument("--speed", type=float, default=1.0, help="run the model at K times real time (default 1)")
    p.add_argument("--tcp", metavar="[HOST:]PORT", type=_tcp_address,
                   help="also serve the socket GLI over TCP (loopback by default); applications prove that they "
                        "hold the token of --tcp-token")
    p.add_argument("--tcp-token", metavar="FILE",
                   help="the TCP GLI's secret (default RUNTIME/tcp.token; made 0640 for --group if absent): copy "
                        "it to the hosts whose applications connect over TCP")
    p.add_argument("--web", metavar="[ADDR:]PORT", type=_web_address,
                   help="serve the live operator view in a browser (loopback by default; port 0: any free one); "
                        "pages prove the token of --tcp-token, and `hilgate view` prints the address with it")
    p.add_argument("--auth-timeout", type=_handshake_seconds, default=5.0, metavar="S",
                   help="how long a --tcp or --web connection has, from its connection on, to prove the token "
                        "(default 5; the handshake is one round trip)")
    p.add_argument("--runtime-dir", help="where the sockets go (default: $RUNTIME_DIRECTORY, /run/hilgate, "
                                          "$XDG_RUNTIME_DIR/hilgate or /tmp/hilgate-UID)")
    p.add_argument("--trace", help="append the event trace (JSON lines) here")
    p.add_argument("--summary", help="write the summary (JSON) here on exit")
    p.add_argument("--until", type=float, help="stop after this many model seconds")
    p.add_argument("--status-line", action=argparse.BooleanOptionalAction, default=None,
                   help="a live status line on stderr (default: when it is a terminal)")
    p.add_argument("--realtime", action="store_true",
                   help="run the loop at real-time priority (SCHED_RR 10, memory locked) where the host "
                        "allows it (CAP_SYS_NICE or RLIMIT_RTPRIO: the systemd unit allows it), else at the lowest "
                        "niceness allowed; the log and `hilgate status` say which")
    p.add_argument("--realtime-priority", type=int, default=None, metavar="N",
                   help="--realtime at priority N (1-99) instead of 10")

    p.add_argument("--gli-backlog", type=int, default=1000, metavar="N",
                   help="frames kept per link while an application's receive queue is full (default 1000); "
                        "beyond that they are dropped and counted")
    p.add_argument("--group", metavar="GROUP",
                   help="the group whose members may use the sockets and queues (default: the daemon's own "
                        "group; the systemd unit runs as group hilgate)")
    p.add_argument("--max-clients", type=int, default=256, metavar="N",
                   help="socket GLI clients at once, all links together (default 256)")
    p.add_argument("--host", metavar="NAME",
                   help="this daemon's host in a scene spread over hosts (default: the machine's host name)")
    p.add_argument("--zenoh-connect", action="append", default=[], metavar="ENDPOINT", type=_zenoh_endpoint,
                   help="a daemon to join, e.g. tcp/192.168.1.10:7447 (repeatable; besides the scene's zenoh.connect)")
    p.add_argument("--zenoh-listen", action="append", default=[], metavar="ENDPOINT", type=_zenoh_endpoint,
                   help="where the others may connect (default: the scene's zenoh.listen, else loopback only)")
    p.add_argument("--zenoh-credentials", metavar="DIR",
                   help="the lab's credentials (hilgate network init; DIR or DIR/hosts/HOST): overrides zenoh.credentials")
    p.add_argument("--zenoh-insecure", action="store_true",
                   help="join without credentials: plain TCP, no access control (as zenoh.insecure: true)")
    p.add_argument("--clock-offset-s", type=float, default=0.0, metavar="S",
                   help="act as if this host's clock were S seconds ahead (to measure what an offset does)")
    p.add_argument("--max-link-clients", type=int, default=32, metavar="N",
                   help="socket GLI clients at once on one link (default 32)")

    e = sub.add_parser("emulate", help="run a scene with one simulated link shown as a modem device "
                                       "(EvoLogics, S100, Modem-M64, Micro-Modem)")
    e.add_argument("protocol", choices=emulated_protocols())
    _add_scene_args(e, optional=True)
    e.add_argument("--link", required=True, help="the simulated link to expose")
    e.add_argument("--pty", help="link the emulated device's pseudo-terminal here (e.g. /tmp/ttyEVO0)")
    e.add_argument("--tcp", type=int, help="listen on this loopback port instead (EvoLogics only)")
    e.add_argument("--baud", type=int, help="the serial line the emulated S100 paces itself at (default 9600)")
    e.add_argument("--rtscts", action=argparse.BooleanOptionalAction, default=None,
                   help="the emulated S100 has RTS/CTS flow control (default: without, 45 bytes at a time)")
    for action in p._actions:  # the daemon's own options (speed, runtime dir, trace…), not its --tcp
        if action.dest not in ("help", "scene", "overrides", "plugins", "preset_dirs", "tcp") and action.option_strings:
            e._add_action(action)

    p = sub.add_parser("network", help="a lab's credentials for a network of daemons over Zenoh")
    n = p.add_subparsers(dest="network_command", metavar="ACTION")
    n.required = True
    i = n.add_parser("init", help="a CA and a certificate per host and per application (TLS, access control)")
    i.add_argument("directory", help="where the credentials go (made 0750; keys 0600)")
    i.add_argument("--hosts", required=True, metavar="A,B,...", help="the hosts' names (their daemons' --host)")
    i.add_argument("--apps", default="0", metavar="N|A,B,...",
                   help="applications: a number (app-1 … app-N) or names (default 0)")

    p = sub.add_parser("queues", help="list (or --unlink) the dccomms POSIX queues of a scene's links")
    _add_scene_args(p)
    p.add_argument("--unlink", action="store_true", help="remove them (applications must reopen)")

    for name, text in (("status", "show the running daemon's links and vehicles"),):
        p = sub.add_parser(name, help=text)
        p.add_argument("--json", action="store_true", help='one JSON object: {"links": [...], "vehicles": [...]}')
        p.add_argument("--watch", type=float, metavar="S", help="print again every S seconds")
        p.add_argument("--network", action="store_true",
                       help="every host of the network: its links, and how the others hear it (over Zenoh)")
        p.add_argument("--runtime-dir")

    p = sub.add_parser("reload", help="make the running daemon read its scene file again (as SIGHUP); links whose "
                                      "keys changed are reconfigured in place, applications stay connected")
    p.add_argument("--timeout", type=float, default=60.0, metavar="S",
                   help="wait at most S seconds for the daemon's answer (default 60)")
    p.add_argument("--runtime-dir")

    p = sub.add_parser("pose", help="follow the vehicles' poses live")
    p.add_argument("vehicle", nargs="*", help="only these vehicles")
    p.add_argument("--interval", type=float, default=0.5, help="seconds between updates (default 0.5)")
    p.add_argument("--runtime-dir")

    p = sub.add_parser("report", help="figures (and --csv tables) of a trace, and of summaries side by side")
    p.add_argument("trace", help="a trace written by --trace")
    p.add_argument("summaries", nargs="*", help="summaries written by --summary, compared flow by flow")
    p.add_argument("--out", required=True, help="the folder for the figures and index.html")
    p.add_argument("--vehicles", nargs="+", help="vehicles whose distances to plot (default: the first four)")
    p.add_argument("--csv", action="store_true", help="also write the tables behind the figures")
    p.add_argument("--title", help="the page's title")
    p.add_argument("--window", type=float, nargs=2, metavar=("START", "END"), help="only these seconds of the trace")
    p.add_argument("--format", dest="formats", action="append", choices=["svg", "pdf"],
                   help="also write each figure as SVG or PDF (vector, for a paper; repeatable)")
    p.add_argument("--width", type=float, metavar="INCHES",
                   help="draw the figures this wide, e.g. 3.5 for one column of a paper (default 9, the bars of "
                        "many flows wider; text keeps its size, tick labels are thinned where they would overlap)")
    p.add_argument("--dpi", type=float, metavar="N",
                   help="the PNGs' resolution in dots per inch (default 300, what journals ask; 600 or more for "
                        "line art); SVG and PDF are vector")
    p.add_argument("--captions", action="store_true",
                   help="also draw each figure's caption under it (it is always in the file's metadata and "
                        "index.html; a journal sets captions itself)")
    p.add_argument("--run", metavar="ID|N", help="a trace the daemon appended to across restarts holds several runs: "
                                                 "this one (its id, or 1 for the first, -1 the last; default the last)")
    p.add_argument("--water", metavar="SCENE", help="also draw each channel with water's BELLHOP transmission loss "
                                                    "with the vehicles' tracks over it (water-CHANNEL.png)")

    p = sub.add_parser("view", help="the operator's view in a browser: play a trace (play, pause, speed, a time "
                                    "slider), or without TRACE print the running daemon's address (hilgate run --web)")
    p.add_argument("trace", nargs="?", help="a trace of hilgate sim or hilgate run")
    p.add_argument("--web", metavar="[ADDR:]PORT", type=_web_address, default="0",
                   help="where to serve it (default: any free port on loopback)")
    p.add_argument("--run", metavar="ID|N", help="which run of a daemon's trace (its id, or 1 for the first, -1 the "
                                                 "last; default the last)")
    p.add_argument("--scene", help="the scene, for a trace that names none (hilgate sim's traces)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a value of --scene, as for sim")
    p.add_argument("--token-file", metavar="FILE",
                   help="pages prove this file's token (default: a new one for this run, printed in the address)")
    p.add_argument("--runtime-dir", help="without TRACE: the daemon's runtime directory")

    p = sub.add_parser("app", help="run an application (hilgate.app.Application) against a running daemon")
    p.add_argument("application", metavar="MODULE:CLASS", help="a module name or a .py file, and the class")
    p.add_argument("--link", dest="links", action="append", required=True, metavar="ID",
                   help="a link the application uses (repeatable; ctx.links in this order)")
    p.add_argument("--param", dest="params", action="append", default=[], metavar="KEY=VALUE",
                   help="ctx.params[KEY] (VALUE read as YAML: 10, 0.5, true, [1, 2], text)")
    p.add_argument("--name", help="the application's name (default: the class name; seeds ctx.random)")
    p.add_argument("--seed", type=int, help="seed of ctx.random (default: not reproducible)")
    p.add_argument("--until", type=float, metavar="S", help="stop after S seconds (default: SIGTERM/SIGINT)")
    p.add_argument("--tcp", metavar="[HOST:]PORT", type=_tcp_address, help="the daemon's TCP GLI listener")
    p.add_argument("--token-file", metavar="FILE", help=TOKEN_HELP)
    _add_zenoh_args(p)
    p.add_argument("--runtime-dir")

    p = sub.add_parser("send", help="send text to a link (arguments, or one frame per stdin line)")
    p.add_argument("link")
    p.add_argument("text", nargs="*")
    p.add_argument("--to", type=_address, default=255, help="destination address (default 255, broadcast)")
    p.add_argument("--tcp", metavar="[HOST:]PORT", type=_tcp_address)
    p.add_argument("--token-file", metavar="FILE", help=TOKEN_HELP)
    _add_zenoh_args(p)
    p.add_argument("--runtime-dir")

    p = sub.add_parser("listen", help="print what a link receives")
    p.add_argument("link")
    p.add_argument("--count", type=int, help="stop after N frames")
    p.add_argument("--timeout", type=float, help="stop after S seconds without a frame")
    p.add_argument("--hex", action="store_true", help="print payloads in hex")
    p.add_argument("--tcp", metavar="[HOST:]PORT", type=_tcp_address)
    p.add_argument("--token-file", metavar="FILE", help=TOKEN_HELP)
    _add_zenoh_args(p)
    p.add_argument("--runtime-dir")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:
        # `hilgate send LINK --to 2 hello world`: argparse cannot give a '*' positional what follows
        # an option, so the words after it arrive here; anything else unknown is still an error.
        if args.command == "send" and not any(word.startswith("-") for word in extra):
            args.text = [*args.text, *extra]
        else:
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
    from .logsetup import setup_logging

    setup_logging(args.verbose, daemon=args.command in ("run", "emulate"))
    try:
        code = COMMANDS[args.command](args)
        sys.stdout.flush()  # here, not at exit, so that a reader that has gone is noticed below
        return code
    except SceneError as exc:
        print(f"hilgate: {exc}", file=sys.stderr)
        return EXIT_SCENE
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError as exc:
        if _output_closed():
            return _quiet_after_closed_pipe()
        print(f"hilgate: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"hilgate: {exc}", file=sys.stderr)
        return getattr(exc, "exit_status", 1)  # (2 where trying again cannot help: an extra not installed)
    except Exception as exc:  # a client tool's error (GliError, …): one line, no traceback
        from .channel.runner import BellhopError
        from .gli.socket_client import GliError

        if isinstance(exc, (GliError, BellhopError)):
            print(f"hilgate: {exc}", file=sys.stderr)
            return 1
        raise


def _output_closed() -> bool:
    """Whether the reader of stdout (or stderr) has gone, as with ``hilgate pose | head``: the pipe's
    write end then polls as an error.  A broken socket to the daemon is not that, and is reported."""
    import select

    poll = select.poll()
    for stream in (sys.stdout, sys.stderr):
        try:
            poll.register(stream.fileno(), select.POLLOUT)
        except (ValueError, OSError, AttributeError):
            continue
    try:
        return any(events & (select.POLLERR | select.POLLHUP) for _, events in poll.poll(0))
    except OSError:
        return False


def _quiet_after_closed_pipe() -> int:
    """Nothing more can be said where nobody reads: point stdout at /dev/null so that the interpreter's
    last flush cannot complain either, and end as a process killed by SIGPIPE would (128 + 13)."""
    import os

    devnull = os.open(os.devnull, os.O_WRONLY)
    for stream in (sys.stdout, sys.stderr):
        try:
            os.dup2(devnull, stream.fileno())
        except (ValueError, OSError, AttributeError):
            pass
    os.close(devnull)
    return 141


if __name__ == "__main__":
    sys.exit(main())
