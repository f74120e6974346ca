"""Who may talk to the daemon, and one daemon per link id on a host.

The control socket can reload the daemon and the GLI sockets inject frames on any link, so they are
for the daemon's user and group only: the runtime directory is 0750 and every socket 0660, owned by
the daemon's group (``hilgate`` under systemd; ``--group`` when run by hand).  A runtime directory
that someone else owns, or a symlink, is refused: ``/tmp/hilgate-UID`` is a name anyone can take first.

A link id is served by one daemon of a user.  Two daemons that both opened ``/X_tx_dlnk_phy`` would
split one application's frames between them; each daemon therefore holds, for every link it serves, a
lock (``flock``) on ``ID.lock`` in the user's lock directory (:func:`lock_directory`: one for all of the
user's runtime directories, that only the user may enter).  The kernel releases it when the process
dies, and the holder writes its pid there so that a second daemon can say which process holds it.
Another user cannot take the name first: an abstract Unix socket, the lock before issue 37, could be
bound by anyone, and kept the link from starting; a daemon of another user that wants the link's
queues is refused by their owner (:mod:`hilgate.gli.queues`).
"""

from __future__ import annotations

import errno
import fcntl
import grp
import hashlib
import logging
import os
import pwd
import re
import resource
import stat

from ..core.safepath import PathError, open_directory
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
    try:  # as a trace's directory: another user's link on the way would put the sockets where they chose
        os.close(open_directory(parent))
    except PathError as exc:
        raise AccessError(f"runtime directory {path}: {exc}") from None
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


LOCK_DIR_ROOT = "/run/hilgate-links"
"""Root's lock directory: in /run, where only root may create a name."""


def lock_directory(runtime_dir: str) -> str:
    """Where this user's daemons keep their links' locks: the same directory whatever their runtime
    directory (so that two of them meet there), in a place nobody else may create it first: /run for
    root, ``$XDG_RUNTIME_DIR`` (the user's own, 0700) for the others; without one, the runtime
    directory (then only daemons with the same runtime directory meet)."""
    if os.geteuid() == 0:
        return LOCK_DIR_ROOT
    private = os.environ.get("XDG_RUNTIME_DIR", "")
    if private and os.path.isabs(private):
        try:
            info = os.lstat(private)
        except OSError:
            info = None
        if info is not None and stat.S_ISDIR(info.st_mode) and info.st_uid == os.geteuid() \
                and not info.st_mode & 0o022:
            return os.path.join(private, "hilgate-links")
    return os.path.join(runtime_dir, "links")


def prepare_lock_directory(path: str) -> None:
    """Create ``path`` 0700, or check that it is a real directory of this user's (then make it 0700):
    nobody else may even open a lock in it (a read-only descriptor can hold a flock too)."""
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    except OSError as exc:
        raise AccessError(f"cannot make the links' lock directory {path}: {exc.strerror or exc}") from None
    info = os.lstat(path)
    if stat.S_ISLNK(info.st_mode) or not stat.S_ISDIR(info.st_mode) or info.st_uid != os.geteuid():
        raise AccessError(f"the links' lock directory {path} is not a directory of {_describe_owner(os.geteuid())}: "
                          f"refusing it; remove it")
    if stat.S_IMODE(info.st_mode) != 0o700:
        os.chmod(path, 0o700)


_PLAIN_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,200}")


def _lock_file(link_id: str) -> str:
    if _PLAIN_ID.fullmatch(link_id):
        return f"{link_id}.lock"
    return "#" + hashlib.sha256(link_id.encode()).hexdigest() + ".lock"


HOLDER_COMMAND_MAX = 2000
"""Characters of the holder's command line an error shows: whole for any real command line (its scene
path is at the end), bounded for one made up."""


def _holder(fd: int) -> str:
    """Which process holds the lock open as ``fd``, for the error message: the pid it wrote there."""
    try:
        pid = int(os.pread(fd, 32, 0).split()[0])
        uid = os.stat(f"/proc/{pid}").st_uid
    except (OSError, ValueError, IndexError):
        return "another process"
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as handle:
            raw = handle.read(HOLDER_COMMAND_MAX + 1)
        command = raw[:HOLDER_COMMAND_MAX].replace(b"\0", b" ").decode(errors="replace").strip()
        if not command.isprintable():  # one line, whatever is in its arguments
            command = command.encode("unicode_escape").decode("ascii")
        if len(raw) > HOLDER_COMMAND_MAX:
            command += " …"
    except OSError:
        command = "?"
    return f"process {pid} of {_describe_owner(uid)}: {command}"


class LinkLock:
    """Held while this daemon serves ``link_id``; :class:`AccessError` if another process holds it.
    ``directory``: the user's lock directory (:func:`lock_directory`, made by
    :func:`prepare_lock_directory`)."""

    def __init__(self, link_id: str, directory: str):
        self.link_id = link_id
        self.directory = directory
        self.name = _lock_file(link_id)
        self.fd = self._take()

    def _take(self) -> int:
        path = os.path.join(self.directory, self.name)
        for _ in range(100):  # a holder that removes the file as we open it: open the new one
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
            except OSError as exc:
                raise AccessError(f"cannot lock link {self.link_id} ({path}): {exc.strerror or exc}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = _holder(fd)
                os.close(fd)
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN):
                    raise AccessError(f"cannot lock link {self.link_id} ({path}): {exc.strerror or exc}") from None
                raise AccessError(f"link {self.link_id} is already served on this host by {holder}; a link id may "
                                  f"be served by one daemon only (stop it, or remove the link from one of the "
                                  f"scenes)") from None
            try:
                same = os.stat(path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
                return fd
            os.close(fd)  # locked a file its holder had just removed: take the one at the name now
        raise AccessError(f"cannot lock link {self.link_id} ({path}): it keeps being replaced")

    def release(self) -> None:
        if self.fd < 0:
            return
        try:  # removed while still held: whoever opens the name next makes a new file and locks that
            os.unlink(os.path.join(self.directory, self.name))
        except OSError:
            pass
        os.close(self.fd)
        self.fd = -1
