"""Who may talk to the daemon, and one daemon per link id on a host.

The control socket can reload the daemon and the GLI sockets inject frames on any link, so they are
for the daemon's user and group only: the runtime directory is 0750 and every socket 0660, owned by
the daemon's group (``hilgate`` under systemd; ``--group`` when run by hand).  A runtime directory
that someone else owns, or a symlink, is refused: ``/tmp/hilgate-UID`` is a name anyone can take first.

A link id is served by one daemon per host.  Two daemons that both opened ``/X_tx_dlnk_phy`` would
split one application's frames between them; each daemon therefore holds, for every link it serves,
an abstract Unix socket named after the id.  The kernel releases it when the process dies (no stale
lock files after a crash), and the second daemon asks the holder's credentials (SO_PEERCRED) to say
which process holds it.
"""

from __future__ import annotations

import grp
import hashlib
import logging
import os
import pwd
import resource
import socket
import stat
import struct

from ..scene.yaml_nodes import SceneError

log = logging.getLogger(__name__)


class AccessError(OSError):
    """The daemon cannot start (or add a link) safely; the message says what to change."""


def resolve_group(name: str | None) -> int | None:
    """The gid of ``name`` (a group name or number), or None for the process's own group;
    :class:`SceneError` (a configuration error) if there is no such group."""
    if not name:
        return None
    try:
        return grp.getgrnam(name).gr_gid
    except KeyError:
        if name.isdigit():
            return int(name)
        # a configuration error (exit status 2, which systemd does not restart), as a bad scene is
        raise SceneError("--group", 0, "", f"no group {name!r} (create it, e.g. `groupadd --system {name}`)") from None


def _describe_owner(uid: int) -> str:
    try:
        return f"{pwd.getpwuid(uid).pw_name} (uid {uid})"
    except KeyError:
        return f"uid {uid}"


def prepare_private_dir(path: str, group: int | None = None) -> None:
    """Create ``path`` as 0750, or check that an existing one is a real directory of this user's
    (then give it mode 0750 and the group), and refuse anything else."""
    parent = os.path.dirname(os.path.abspath(path))
    os.makedirs(parent, exist_ok=True)
    try:
        os.mkdir(path, 0o750)
    except FileExistsError:
        pass
    info = os.lstat(path)
    if stat.S_ISLNK(info.st_mode) or not stat.S_ISDIR(info.st_mode):
        raise AccessError(f"runtime directory {path} is not a directory (a symlink or a file): refusing it; "
                          f"remove it or give --runtime-dir")
    if info.st_uid != os.geteuid():
        raise AccessError(f"runtime directory {path} belongs to {_describe_owner(info.st_uid)}, not to "
                          f"{_describe_owner(os.geteuid())}: anyone can create such a name first; refusing it. "
                          f"Remove it or give --runtime-dir")
    if stat.S_IMODE(info.st_mode) != 0o750:
        os.chmod(path, 0o750)
    if group is not None and info.st_gid != group:
        try:
            os.chown(path, -1, group)
        except PermissionError:
            raise AccessError(f"cannot give {path} to group {group}: this user is not a member of it") from None


def raise_descriptor_limit() -> None:
    """Each link holds two queue descriptors, a listening socket and a lock: lift the soft limit on
    open files to the hard one so that hundreds of links fit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != hard:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
        except (ValueError, OSError):
            pass


def _lock_name(link_id: str) -> bytes:
    name = f"hilgate/link/{link_id}"
    if len(name) > 100:
        name = "hilgate/link#" + hashlib.sha256(link_id.encode()).hexdigest()
    return b"\0" + name.encode()


HOLDER_COMMAND_MAX = 2000
"""Characters of the holder's command line an error shows: whole for any real command line (its scene
path is at the end), bounded for one another local user made up."""


def holder_of(link_id: str) -> str:
    """Which process holds ``link_id``'s lock, for the error message."""
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.settimeout(1.0)
        probe.connect(_lock_name(link_id))
        pid, uid, _gid = struct.unpack("3i", probe.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, 12))
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as handle:
                raw = handle.read(HOLDER_COMMAND_MAX + 1)
            command = raw[:HOLDER_COMMAND_MAX].replace(b"\0", b" ").decode(errors="replace").strip()
            if not command.isprintable():  # one line, whatever another local user put in its arguments
                command = command.encode("unicode_escape").decode("ascii")
            if len(raw) > HOLDER_COMMAND_MAX:  # whole, unless another local user made it absurdly long
                command += " …"
        except OSError:
            command = "?"
        return f"process {pid} of {_describe_owner(uid)}: {command}"
    except OSError:
        return "another process"
    finally:
        probe.close()


class LinkLock:
    """Held while this daemon serves ``link_id``; :class:`AccessError` if another process holds it."""

    def __init__(self, link_id: str):
        self.link_id = link_id
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        try:
            self.sock.bind(_lock_name(link_id))
            self.sock.listen(1)  # only so that a second daemon can ask who holds it
        except OSError:
            self.sock.close()
            raise AccessError(f"link {link_id} is already served on this host by {holder_of(link_id)}; "
                              f"a link id may be served by one daemon only (stop it, or remove the link from "
                              f"one of the scenes)") from None

    def release(self) -> None:
        self.sock.close()
