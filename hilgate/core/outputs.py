"""What hilgate writes on the file system, and the rules that keep it from writing anything else.

A scene names two kinds of paths that hilgate writes: its trace file (``trace: {file}``) and the pty
links of its emulated modems (``emulate: {pty}``); the command line adds ``--trace`` and ``--summary``.
Nothing else is created, truncated or removed, and these only within the rules below, checked when
the scene loads (``FILE:LINE``) and again, on the open descriptor, when the file is written (the file
system may have changed in between):

- **Traces and summaries** go into a regular file that does not exist yet (created ``0640``, group the
  daemon's), or is this user's, not writable by others, and empty or already one of hilgate's (a
  trace's first bytes are ``{"t":``, a summary's ``{``).  Never through a symbolic link at the end, nor
  through another user's link to a directory on the way (:mod:`hilgate.core.safepath`), never into a
  device, FIFO or directory, never into a file with other content (``trace: {file: /etc/passwd}`` is
  refused, not appended to or truncated), and never into one another user made first (an empty 0666
  file would let them read the trace).
- **Pty links** are symbolic links to ``/dev/pts/N``.  One is created only where nothing is (never
  replacing a file, and ``symlink(2)`` itself never replaces), an existing one only if it is such a
  link (a previous run's); at stop the daemon removes the link only if it still points at its own pty.
  Its directory is reached as a trace's is, once, and the link is made, read and removed by name in it.
"""

from __future__ import annotations

import logging
import os
import re
import stat
from typing import TextIO

from .safepath import PathError, open_parent

log = logging.getLogger(__name__)

PTY_TARGET = re.compile(r"/dev/pts/[0-9]{1,9}")
SIGNATURES = {"trace": b'{"t":', "summary": b"{"}
FILE_MODE = 0o640


class OutputError(OSError):
    """hilgate will not write there; the message (one line) says why and what to do."""


def pty_link_problem(path: str) -> str | None:
    """Why an emulated modem's pty link may not be made at ``path`` (something that is not a pty link
    is there, or another user's link to a directory is on the way), or None."""
    try:
        parent, name = open_parent(path)
    except PathError as exc:
        return None if exc.missing else str(exc)
    except OSError as exc:
        return f"cannot look at {path}: {exc.strerror or exc}"
    try:
        return pty_link_problem_at(parent, name, path)
    finally:
        os.close(parent)


def pty_link_problem_at(parent: int, name: str, path: str) -> str | None:
    """:func:`pty_link_problem` for ``name`` in the directory open as ``parent``."""
    try:
        info = os.stat(name, dir_fd=parent, follow_symlinks=False)
    except FileNotFoundError:
        return None
    except OSError as exc:
        return f"cannot look at {path}: {exc.strerror or exc}"
    if stat.S_ISLNK(info.st_mode):
        try:
            target = os.readlink(name, dir_fd=parent)
        except OSError as exc:
            return f"cannot read the link {path}: {exc.strerror or exc}"
        if PTY_TARGET.fullmatch(target):
            return None
        return f"{path} exists and is a link to {target[:100]!r}, not to a pty: hilgate replaces only a pty link"
    return f"{path} exists and is not a pty link (a {_kind(info.st_mode)}): hilgate will not replace it"


def output_problem(path: str, kind: str) -> str | None:
    """Why hilgate may not write its ``kind`` (``trace`` or ``summary``) at ``path``, or None.  Looks
    without following another user's link to a directory, or any link at the end, and without opening
    anything but a regular file."""
    try:
        parent, name = open_parent(path)
    except PathError as exc:
        return None if exc.missing else str(exc)  # (nothing there yet: the open says so, if it still is not)
    except OSError as exc:
        return f"cannot look at {path}: {exc.strerror or exc}"
    try:
        return _problem_at(parent, name, path, kind)
    finally:
        os.close(parent)


def _problem_at(parent: int, name: str, path: str, kind: str) -> str | None:
    try:
        info = os.stat(name, dir_fd=parent, follow_symlinks=False)
    except FileNotFoundError:
        return None
    except OSError as exc:
        return f"cannot look at {path}: {exc.strerror or exc}"
    if not stat.S_ISREG(info.st_mode):
        return f"{path} is a {_kind(info.st_mode)}, not a regular file: hilgate writes its {kind} only into one"
    problem = _owner_problem(info, path, kind)
    if problem is not None or info.st_size == 0:
        return problem
    try:
        fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY, dir_fd=parent)
    except OSError as exc:
        return f"cannot read {path}: {exc.strerror or exc}"
    try:
        return _content_problem(fd, path, kind)
    finally:
        os.close(fd)


def _owner_problem(info: os.stat_result, path: str, kind: str) -> str | None:
    """An existing file must be this user's, and not writable by others: a file another user made
    beforehand (empty, 0666) is theirs to read the trace from, or to truncate under the daemon."""
    if info.st_uid != os.geteuid():
        return (f"{path} belongs to uid {info.st_uid}, not to this user: hilgate writes its {kind} only into "
                f"its own file (remove it, or give a new name)")
    if info.st_mode & stat.S_IWOTH:
        return (f"{path} is writable by others (mode {stat.S_IMODE(info.st_mode):04o}): whoever may write it "
                f"may read the {kind} too; `chmod o-w` it if nobody else wrote it, or give a new name")
    return None


def _content_problem(fd: int, path: str, kind: str) -> str | None:
    signature = SIGNATURES[kind]
    start = os.pread(fd, len(signature), 0)
    if start and start != signature:
        return (f"{path} holds something that is not a hilgate {kind}: hilgate will not write into it "
                f"(give a new file)")
    return None


def open_output(path: str, kind: str, *, append: bool, group: int | None = None,
                buffering: int = -1) -> TextIO:
    """``path`` opened for hilgate's ``kind`` within the module's rules: appended to (a daemon's trace
    across restarts) or emptied first; created ``0640`` for ``group`` (default: the process's).  The
    file is opened in the directory reached by :func:`hilgate.core.safepath.open_parent`, by name."""
    flags = os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY | (os.O_APPEND if append else 0)
    try:
        parent, name = open_parent(path)
    except PathError as exc:
        raise OutputError(f"cannot write the {kind} {path}: {exc}" if exc.missing else str(exc)) from None
    except OSError as exc:
        raise OutputError(_open_problem(path, kind, exc)) from None
    created = False
    try:
        problem = _problem_at(parent, name, path, kind)
        if problem is not None:
            raise OutputError(problem)
        try:
            fd = os.open(name, flags | os.O_CREAT | os.O_EXCL, FILE_MODE, dir_fd=parent)
            created = True
        except FileExistsError:
            try:
                fd = os.open(name, flags, dir_fd=parent)
            except OSError as exc:
                raise OutputError(_open_problem(path, kind, exc)) from None
        except OSError as exc:
            raise OutputError(_open_problem(path, kind, exc)) from None
    finally:
        os.close(parent)
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):  # swapped in since the look above
            raise OutputError(f"{path} is a {_kind(info.st_mode)}, not a regular file")
        if created:
            os.fchmod(fd, FILE_MODE)  # whatever the umask: the daemon's group reads it, nobody else
            if group is not None and info.st_gid != group:
                try:
                    os.fchown(fd, -1, group)
                except PermissionError:
                    log.warning("cannot give %s to group %d: this user is not a member of it", path, group)
        else:  # the file opened, whatever was there at the look
            problem = _owner_problem(info, path, kind) or (_content_problem(fd, path, kind) if info.st_size else None)
            if problem is not None:
                raise OutputError(problem)
        if not append:
            os.ftruncate(fd, 0)
        os.set_blocking(fd, True)
        return os.fdopen(fd, "a" if append else "w", encoding="utf-8", buffering=buffering)
    except BaseException:
        os.close(fd)
        raise


def _open_problem(path: str, kind: str, exc: OSError) -> str:
    if exc.errno == getattr(os, "ELOOP", 40):  # (by name: a constant not every platform has)
        return f"{path} is a symbolic link: hilgate writes its {kind} only into a regular file, not through a link"
    return f"cannot write the {kind} {path}: {exc.strerror or exc}"


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISLNK, "symbolic link"), (stat.S_ISDIR, "directory"), (stat.S_ISFIFO, "FIFO"),
                       (stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"),
                       (stat.S_ISSOCK, "socket"), (stat.S_ISREG, "regular file")):
        if test(mode):
            return name
    return "special file"
