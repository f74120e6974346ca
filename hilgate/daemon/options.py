"""What ``hilgate run`` was asked for: the daemon's options, in one value.

Why one value: the daemon, its door table and its start line all read them; passed as one frozen object
they cannot drift apart, and a door of a plug-in reads the option it needs by name."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DaemonOptions", "parse_tcp"]


@dataclass(frozen=True)
class DaemonOptions:
    """The command line of ``hilgate run`` (the field order is ``Daemon``'s positional parameters)."""

    scene_path: str
    overrides: tuple[str, ...] = ()
    runtime_dir: str = ""
    speed: float = 1.0
    tcp: str | None = None
    trace_path: str | None = None
    summary_path: str | None = None
    until: float | None = None
    status_line: bool = False
    gli_backlog: int = 1000
    group: str | None = None
    max_clients: int = 256
    max_link_clients: int = 32
    plugins: tuple[str, ...] = ()
    preset_dirs: tuple[str, ...] = ()
    host: str | None = None
    zenoh_connect: tuple[str, ...] = ()
    zenoh_listen: tuple[str, ...] = ()
    clock_offset_s: float = 0.0
    tcp_token: str | None = None
    zenoh_credentials: str | None = None
    zenoh_insecure: bool = False
    web: str | None = None
    auth_timeout_s: float = 5.0
    realtime_priority: int = 0

    def __post_init__(self) -> None:
        # (the command line gives lists: kept as tuples, so the options stay a value)
        for name, value in (("overrides", self.overrides), ("plugins", self.plugins), ("preset_dirs", self.preset_dirs),
                            ("zenoh_connect", self.zenoh_connect), ("zenoh_listen", self.zenoh_listen)):
            object.__setattr__(self, name, tuple(value or ()))


def parse_tcp(value: str) -> tuple[str, int]:
    """``PORT`` or ``HOST:PORT``; loopback unless a host is given.  ValueError says what is wrong."""
    host, _, port = str(value).rpartition(":")
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"{value!r} is not [HOST:]PORT with a port from 1 to 65535")
    return (host.strip("[]") or "127.0.0.1"), int(port)
