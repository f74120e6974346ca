"""``hilgate run``: the daemon, its router (link id → backend), control socket, live pose sources,
access rules and paths."""

from .service import Daemon, parse_tcp

__all__ = ["Daemon", "parse_tcp"]
