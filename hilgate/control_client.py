"""A client of a daemon's control socket (``RUNTIME/control.sock``, docs/daemon.md): ``hilgate status``,
``reload`` and ``pose``, the benchmarks and the examples speak to a running daemon through this one piece
rather than each writing the socket, the VERSION line and the JSON lines again.

    from hilgate.control_client import request
    links = request({"class": "STATUS"}, runtime_dir)["links"]
"""

from __future__ import annotations

import json
import os
import socket
from typing import Any, Iterator

from .core import safejson
from .core.paths import client_runtime_dir

__all__ = ["Control", "ControlError", "ControlClosed", "request"]

MAX_ANSWER = 16 << 20
"""Characters of the longest answer line read (a STATUS of thousands of links is a few MB): a socket
that sends more without a line's end is not a daemon, and is not given the memory."""


class ControlError(ConnectionError):
    """The daemon's socket closed, or said something that is no answer (an OSError: ``hilgate status``
    prints it as one line)."""


class ControlClosed(ControlError):
    """The daemon closed the connection (the end of :meth:`Control.replies`; elsewhere an error)."""


class Control:
    """One connection to the control socket of the daemon serving ``runtime_dir`` (None: the first
    directory where a daemon listens).  The daemon's first line, its VERSION, is read on connecting
    (``version``); an OSError says there is no daemon there."""

    def __init__(self, runtime_dir: str | None = None, timeout: float | None = 5.0):
        self.path = os.path.join(client_runtime_dir(runtime_dir), "control.sock")
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(timeout)
        try:
            self.sock.connect(self.path)
        except OSError as exc:
            self.sock.close()
            raise OSError(f"no hilgate daemon at {self.path} ({exc.strerror or exc})") from None
        self.reader = self.sock.makefile("r", encoding="utf-8")
        try:
            self.version: dict[str, Any] = self._answer()
        except BaseException:
            self.close()
            raise

    def send(self, message: dict) -> None:
        """A request whose answers are read with :meth:`replies` (WATCH)."""
        self.sock.sendall((json.dumps(message) + "\n").encode())

    def request(self, message: dict) -> dict:
        """A request and its one answer."""
        self.send(message)
        return self._answer()

    def replies(self) -> Iterator[dict]:
        """Each line the daemon sends from now on, until it closes the connection."""
        while True:
            try:
                yield self._answer()
            except ControlClosed:
                return

    def _answer(self) -> dict:
        """The next line as a JSON object, read with bounds: a dead or hostile socket is a ControlError,
        never a traceback (a line nested past the parser's recursion, not UTF-8), a hang on a line
        without end, or memory without bound."""
        try:
            line = self.reader.readline(MAX_ANSWER + 1)
        except UnicodeDecodeError:
            raise ControlError(f"{self.path} sent something that is not an answer (not UTF-8)") from None
        if not line:
            raise ControlClosed(f"the daemon at {self.path} closed the connection")
        if not line.endswith("\n"):
            if len(line) > MAX_ANSWER:
                raise ControlError(f"{self.path} sent a line longer than {MAX_ANSWER} characters")
            raise ControlClosed(f"the daemon at {self.path} closed the connection mid-answer")
        try:
            answer = safejson.loads(line, max_bytes=4 * MAX_ANSWER)
        except ValueError as exc:
            raise ControlError(f"{self.path} sent something that is not an answer ({exc})") from None
        if not isinstance(answer, dict):
            raise ControlError(f"{self.path} sent something that is not an answer (not a JSON object)")
        return answer

    def settimeout(self, timeout: float | None) -> None:
        self.sock.settimeout(timeout)

    def close(self) -> None:
        self.reader.close()
        self.sock.close()

    def __enter__(self) -> "Control":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def request(message: dict, runtime_dir: str | None = None, timeout: float | None = 10.0) -> dict:
    """One request on a connection of its own, and its answer."""
    with Control(runtime_dir, timeout) as control:
        return control.request(message)
