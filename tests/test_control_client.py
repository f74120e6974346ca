"""The control-socket client (hilgate.control_client) against a daemon that is dead or hostile: a
socket that closes at once, answers that are not JSON objects, nested past the parser's recursion,
not UTF-8, or a line without end.  Each is one clear error (an OSError, which ``hilgate status``
prints as one line), never a traceback, a hang or memory without bound."""

from __future__ import annotations

import os
import socket
import threading

import pytest

from hilgate import control_client
from hilgate.cli import main
from hilgate.control_client import Control, ControlError

VERSION = b'{"class":"VERSION","version":"0.1.0"}\n'


class FakeDaemon:
    """A real Unix socket at RUNTIME/control.sock that answers with ``script``: bytes to send on
    connecting, then for each request line the next answer (None: close)."""

    def __init__(self, runtime: str, greeting: bytes | None, answers: list[bytes | None] = ()):
        self.path = os.path.join(runtime, "control.sock")
        self.server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.server.bind(self.path)
        self.server.listen(4)
        self.greeting, self.answers = greeting, list(answers)
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        conn, _ = self.server.accept()
        with conn:
            conn.settimeout(60)  # (a hang guard: the client closes, or the test ends)
            try:
                if self.greeting is None:
                    return
                conn.sendall(self.greeting)
                for answer in self.answers:
                    request = b""
                    while not request.endswith(b"\n"):
                        chunk = conn.recv(4096)
                        if not chunk:
                            return
                        request += chunk
                    if answer is None:
                        return
                    conn.sendall(answer)
                while conn.recv(4096):  # keep it open until the client goes
                    pass
            except OSError:
                pass

    def close(self) -> None:
        self.server.close()
        self.thread.join(60)


@pytest.fixture
def runtime(tmp_path):
    return str(tmp_path)


def _fails(runtime: str, greeting: bytes | None, answers: list, match: str) -> None:
    daemon = FakeDaemon(runtime, greeting, answers)
    try:
        with pytest.raises(ControlError, match=match):
            with Control(runtime, timeout=60) as control:
                control.request({"class": "STATUS"})
    finally:
        daemon.close()


def test_a_daemon_that_closes_at_once_is_a_clear_error(runtime):
    _fails(runtime, None, [], "closed the connection")


def test_a_daemon_that_dies_during_a_request_is_a_clear_error(runtime):
    _fails(runtime, VERSION, [None], "closed the connection")


def test_an_answer_nested_past_the_parser_is_refused_not_a_recursion_error(runtime):
    _fails(runtime, VERSION, [b"[" * 100000 + b"]" * 100000 + b"\n"], "not an answer")


def test_an_answer_that_is_not_an_object_is_refused(runtime):
    _fails(runtime, VERSION, [b"[1, 2]\n"], "not an answer")


def test_an_answer_that_is_not_utf8_is_refused(runtime):
    _fails(runtime, VERSION, [b'{"a": "\xff\xfe"}\n'], "not an answer")


def test_a_line_without_end_is_refused_at_the_bound(runtime, monkeypatch):
    monkeypatch.setattr(control_client, "MAX_ANSWER", 4096)
    _fails(runtime, VERSION, [b"x" * 10000], "longer than 4096")  # (and the daemon keeps it open)


def test_hilgate_status_against_a_dead_daemon_says_one_line(runtime, capsys):
    daemon = FakeDaemon(runtime, VERSION, [None])
    try:
        assert main(["status", "--runtime-dir", runtime]) == 1
    finally:
        daemon.close()
    err = capsys.readouterr().err
    assert err.startswith("hilgate: ") and "closed the connection" in err and "Traceback" not in err
    assert err.count("\n") == 1


def test_a_daemon_that_answers_well_is_read(runtime):
    daemon = FakeDaemon(runtime, VERSION, [b'{"class": "STATUS", "links": []}\n'])
    try:
        with Control(runtime, timeout=60) as control:
            assert control.version["class"] == "VERSION"
            assert control.request({"class": "STATUS"}) == {"class": "STATUS", "links": []}
    finally:
        daemon.close()
