"""The modem side of a pseudo-terminal, for an emulated modem that a lab's software opens as a serial port
(``emulate: {pty: /tmp/evo0}``): what every emulated modem on a pty shares, whatever protocol it speaks."""

from __future__ import annotations

import logging
import os
import stat
import tty
from typing import Any

from hilgate.core.outputs import OutputError, pty_link_problem_at
from hilgate.core.safepath import PathError, open_parent

log = logging.getLogger(__name__)


class PtyHost:
    """The modem side of a pseudo-terminal; the slave end is linked at ``path`` for the application."""

    def __init__(self, path: str, scheduler: Any, on_data, name: str, group: int | None = None):
        self.path = path
        self.scheduler = scheduler
        self.on_data = on_data
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line discipline: a serial line carries bytes
        # /dev/pts/N is the daemon user's with group tty, 0620: give it to the daemon's group instead,
        # so the lab's software (members of that group, as for the GLI) can open it, and nobody else
        try:
            os.fchown(self.slave, -1, os.getegid() if group is None else group)
            os.fchmod(self.slave, 0o660)
        except OSError as exc:
            log.warning("%s: cannot give the pty to the daemon's group: %s", name, exc)
        os.set_blocking(self.master, False)
        self.target = os.ttyname(self.slave)
        try:
            self._link(path)
        except OSError:
            for fd in (self.master, self.slave):
                os.close(fd)
            raise
        scheduler.add_reader(self.master, self._readable)
        self.paused = False
        log.info("%s: emulated modem at %s (%s)", name, path, os.ttyname(self.slave))

    def _link(self, path: str) -> None:
        """Link the pty at ``path``: where nothing is, or over a pty link a previous run left (the scene
        loader checked it too; the file system may have changed since).  symlink(2) never replaces, so
        something that appears meanwhile is refused, not removed.  The directory is reached once, without
        another user's links (:mod:`hilgate.core.safepath`), and kept open: the link is made, read and
        removed by name in it, so nobody can point the removal at stop at another directory."""
        try:
            self.directory, self.name = open_parent(path)
        except PathError as exc:
            raise OutputError(str(exc) if not exc.missing else f"cannot make the pty link {path}: {exc}") from None
        try:
            problem = pty_link_problem_at(self.directory, self.name, path)
            if problem is not None:
                raise OutputError(problem)
            try:  # a previous run's pty link (the look above): made anew
                if stat.S_ISLNK(os.stat(self.name, dir_fd=self.directory, follow_symlinks=False).st_mode):
                    os.unlink(self.name, dir_fd=self.directory)
            except FileNotFoundError:
                pass
            try:
                os.symlink(self.target, self.name, dir_fd=self.directory)
            except FileExistsError:
                raise OutputError(f"{path} appeared while the emulated modem's pty link was being made: "
                                  f"not replacing it") from None
        except BaseException:
            os.close(self.directory)
            raise

    def pause(self) -> None:
        """Stop reading: what the application writes waits in the kernel's pty buffer, and once that is
        full its writes block, as on a real serial port that carries bytes only at its baud rate."""
        if not self.paused:
            self.paused = True
            self.scheduler.remove_reader(self.master)

    def resume(self) -> None:
        if self.paused:
            self.paused = False
            self.scheduler.add_reader(self.master, self._readable)

    def _readable(self) -> None:
        try:
            data = os.read(self.master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return  # nobody has the slave open: nothing to read
        if data:
            self.on_data(self, data)

    def write(self, data: bytes) -> None:
        try:
            os.write(self.master, data)
        except (BlockingIOError, OSError) as exc:
            log.debug("pty %s: %s", self.path, exc)

    def close(self) -> None:
        self.paused = True
        self.scheduler.remove_reader(self.master)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass
        try:
            if os.readlink(self.name, dir_fd=self.directory) == self.target:  # only our own: not one put there since
                os.unlink(self.name, dir_fd=self.directory)
        except OSError:
            pass
        try:
            os.close(self.directory)
        except OSError:
            pass

