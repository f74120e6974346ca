"""Where the daemon keeps its sockets, and which scene it runs when none is named."""

from __future__ import annotations

import importlib.resources
import os
import stat

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
    """The first candidate where a daemon is listening (falls back to the daemon's choice).  A candidate
    anyone could have created first is skipped (:func:`_not_trusted`); an OSError if the fallback is one."""
    if explicit:
        return explicit
    for candidate in runtime_candidates():
        if os.path.exists(os.path.join(candidate, "control.sock")) and _not_trusted(candidate) is None:
            return candidate
    chosen = daemon_runtime_dir()
    problem = _not_trusted(chosen)
    if problem is not None:
        raise OSError(f"{problem}: anyone may create that name first, so it is no daemon of yours; "
                      f"remove it or give --runtime-dir")
    return chosen


def _not_trusted(candidate: str) -> str | None:
    """Why a daemon in ``candidate`` could be anyone's (None: it cannot): a symlink, or a directory of
    another user in a directory anyone may write to (``/tmp/hilgate-UID`` is a name anyone can take;
    the daemon refuses such a directory too, docs/security.md).  Root's is trusted."""
    try:
        info = os.lstat(candidate)
        parent = os.stat(os.path.dirname(os.path.abspath(candidate)))
    except OSError:
        return None  # nothing there yet: nothing to trust or refuse
    if not parent.st_mode & stat.S_IWOTH:
        return None  # only its owner (root for /run) could have put it there
    if stat.S_ISLNK(info.st_mode) or not stat.S_ISDIR(info.st_mode):
        return f"the runtime directory {candidate} is not a directory (a symlink or a file)"
    if info.st_uid not in (os.getuid(), 0):
        return f"the runtime directory {candidate} belongs to uid {info.st_uid}, not to this user"
    return None


def default_scene() -> str:
    """``$HILGATE_SCENE``, else /etc/hilgate/scene.yaml, else the embedded demo scene."""
    if os.environ.get("HILGATE_SCENE"):
        return os.environ["HILGATE_SCENE"]
    if os.path.exists(SYSTEM_SCENE):
        return SYSTEM_SCENE
    return str(importlib.resources.files("hilgate.scenes") / "demo.yaml")
