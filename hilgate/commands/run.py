"""``hilgate run [SCENE]``: the daemon, GLI endpoints for every link in real time (its options serve
``hilgate emulate`` too: :func:`add_daemon_options`)."""

from __future__ import annotations

import argparse
import sys

from ..scene.yaml_nodes import SceneError
from .options import add_scene_args, handshake_seconds, tcp_address, web_address, zenoh_endpoint

NAME = "run"


def add_to(sub) -> argparse.ArgumentParser:
    """``hilgate run``'s parser, among ``sub``'s."""
    p = sub.add_parser("run", help="the daemon: GLI endpoints for every link, in real time")
    add_scene_args(p, optional=True)
    add_daemon_options(p)
    return p


def add_daemon_options(p: argparse.ArgumentParser) -> None:
    """The daemon's own options (speed, runtime dir, trace…), which ``hilgate emulate`` shares."""
    p.add_argument("--speed", type=float, default=1.0, help="run the model at K times real time (default 1)")
    p.add_argument("--tcp", metavar="[HOST:]PORT", type=tcp_address,
                   help="also serve the socket GLI over TCP (loopback by default); applications prove that they "
                        "hold the token of --tcp-token")
    p.add_argument("--tcp-token", metavar="FILE",
                   help="the TCP GLI's secret (default RUNTIME/tcp.token; made 0640 for --group if absent): copy "
                        "it to the hosts whose applications connect over TCP")
    p.add_argument("--web", metavar="[ADDR:]PORT", type=web_address,
                   help="serve the live operator view in a browser (loopback by default; port 0: any free one); "
                        "pages prove the token of --tcp-token, and `hilgate view` prints the address with it")
    p.add_argument("--auth-timeout", type=handshake_seconds, default=5.0, metavar="S",
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
    p.add_argument("--zenoh-connect", action="append", default=[], metavar="ENDPOINT", type=zenoh_endpoint,
                   help="a daemon to join, e.g. tcp/192.168.1.10:7447 (repeatable; besides the scene's zenoh.connect)")
    p.add_argument("--zenoh-listen", action="append", default=[], metavar="ENDPOINT", type=zenoh_endpoint,
                   help="where the others may connect (default: the scene's zenoh.listen, else loopback only)")
    p.add_argument("--zenoh-credentials", metavar="DIR",
                   help="the lab's credentials (hilgate network init; DIR or DIR/hosts/HOST): overrides zenoh.credentials")
    p.add_argument("--zenoh-insecure", action="store_true",
                   help="join without credentials: plain TCP, no access control (as zenoh.insecure: true)")
    p.add_argument("--clock-offset-s", type=float, default=0.0, metavar="S",
                   help="act as if this host's clock were S seconds ahead (to measure what an offset does)")
    p.add_argument("--max-link-clients", type=int, default=32, metavar="N",
                   help="socket GLI clients at once on one link (default 32)")


def run(args: argparse.Namespace) -> int:
    from ..daemon.service import Daemon
    from ..core.paths import daemon_runtime_dir, default_scene
    from ..core.priority import DEFAULT_PRIORITY

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
