"""Where the daemon keeps its sockets, and which scene it runs when none is named."""

from __future__ import annotations

import importlib.resources
import os

SYSTEM_SCENE = "/etc/hilgate/scene.yaml"
SYSTEM_RUNTIME = "/run/hilgate"


def runtime_candidates() -> list[str]:
    """In order of preference: an explicit environment setting, systemd's RuntimeDirectory, the
    system directory, the user's runtime directory, a per-user directory in /tmp."""
    candidates = []
    for variable in ("HILGATE_RUNTIME_DIR", "RUNTIME_DIRECTORY"):
        if os.environ.get(variable):
            candidates.append(os.environ[variable].split(":")[0])
    candidates.append(SYSTEM_RUNTIME)
    if os.environ.get("XDG_RUNTIME_DIR"):
        candidates.append(os.path.join(os.environ["XDG_RUNTIME_DIR"], "hilgate"))
    candidates.append(f"/tmp/hilgate-{os.getuid()}")
    return candidates


def daemon_runtime_dir(explicit: str | None = None) -> str:
    """The first candidate the daemon can write to."""
    if explicit:
        return explicit
    for candidate in runtime_candidates():
        parent = candidate if os.path.isdir(candidate) else os.path.dirname(candidate)
        if os.path.isdir(parent) and os.access(parent, os.W_OK | os.X_OK):
            return candidate
    return runtime_candidates()[-1]


def client_runtime_dir(explicit: str | None = None) -> str:
    """The first candidate where a daemon is listening (falls back to the daemon's choice)."""
    if explicit:
        return explicit
    for candidate in runtime_candidates():
        if os.path.exists(os.path.join(candidate, "control.sock")):
            return candidate
    return daemon_runtime_dir()


def default_scene() -> str:
    """``$HILGATE_SCENE``, else /etc/hilgate/scene.yaml, else the embedded demo scene."""
    if os.environ.get("HILGATE_SCENE"):
        return os.environ["HILGATE_SCENE"]
    if os.path.exists(SYSTEM_SCENE):
        return SYSTEM_SCENE
    return str(importlib.resources.files("hilgate.scenes") / "demo.yaml")
