"""Reaching a file's directory without following another user's symbolic links on the way.

``open("/data/logs/t.jsonl")`` follows every link in the path.  When ``logs`` is a link another user
made (in a directory they may write: /tmp, a shared project folder), that user chooses where the
daemon writes: root wrote its trace into another user's 0700 directory through one (issue 37 item 6).
O_NOFOLLOW guards the last name only, and the kernel's ``fs.protected_symlinks`` only links in sticky
world-writable directories.

So the directory is walked one name at a time, each opened relative to the one before with
O_NOFOLLOW: a symbolic link met on the way is followed only if it belongs to root or to this process's
user (their own choice: ``/var/run -> /run``, a link in the user's home), and refused otherwise in one
line that names it.  Nothing can be swapped in between a look and its use: each step opens what it
looked at, and a link put there after the look fails that open (ELOOP, ENOTDIR) and is refused.  The
caller opens the file relative to the directory's descriptor (``dir_fd``), never through a link.
"""

from __future__ import annotations

import errno
import os
import stat

__all__ = ["PathError", "open_directory", "open_parent"]

MAX_LINKS = 40
"""Links followed in one path at most, as the kernel's own lookup allows."""
# by name: a platform's constant (O_PATH is Linux's); a directory one may search but not list is walked too
_DIRECTORY = getattr(os, "O_PATH", os.O_RDONLY) | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC


class PathError(OSError):
    """The path cannot be used; the message (one line) says which part and why.  ``missing``: a part
    does not exist (no rule was broken: there is nothing there yet)."""

    def __init__(self, message: str, missing: bool = False):
        super().__init__(message)
        self.missing = missing


def open_parent(path: str) -> tuple[int, str]:
    """A descriptor of the directory ``path`` names its file in (reached as the module says) and the
    file's name there; the caller closes the descriptor."""
    head, name = os.path.split(path)
    if name in ("", ".", ".."):
        raise PathError(f"{path} names a directory, not a file")
    return open_directory(head or "."), name


def open_directory(path: str) -> int:
    """A descriptor of the directory ``path``, reached without another user's links; PathError if not."""
    fd = os.open("/" if path.startswith("/") else ".", _DIRECTORY)
    parts = [part for part in path.split("/") if part not in ("", ".")]
    parts.reverse()  # a stack: the next name last
    walked = "/" if path.startswith("/") else ""
    links = 0
    try:
        while parts:
            part = parts.pop()
            shown = os.path.join(walked, part) if walked else part
            try:
                info = os.stat(part, dir_fd=fd, follow_symlinks=False)
            except FileNotFoundError:
                raise PathError(f"{shown} does not exist", missing=True) from None
            if stat.S_ISLNK(info.st_mode):
                if info.st_uid not in (0, os.geteuid()):
                    raise PathError(f"{shown} is a symbolic link of uid {info.st_uid} (another user's): hilgate "
                                    f"does not follow it; give the path without it")
                links += 1
                if links > MAX_LINKS:
                    raise PathError(f"{path}: more than {MAX_LINKS} symbolic links on the way")
                target = os.readlink(part, dir_fd=fd)
                if target.startswith("/"):
                    os.close(fd)
                    fd = os.open("/", _DIRECTORY)
                    walked = "/"
                parts.extend(reversed([p for p in target.split("/") if p not in ("", ".")]))
                continue
            if not stat.S_ISDIR(info.st_mode):
                raise PathError(f"{shown} is not a directory")
            try:
                step = os.open(part, _DIRECTORY, dir_fd=fd)
            except OSError as exc:
                if exc.errno in (errno.ELOOP, errno.ENOTDIR):  # swapped since the look
                    raise PathError(f"{shown} changed while hilgate looked at it: not following it") from None
                raise PathError(f"cannot open {shown}: {exc.strerror or exc}") from None
            os.close(fd)
            fd = step
            walked = shown
        return fd
    except BaseException:
        os.close(fd)
        raise
