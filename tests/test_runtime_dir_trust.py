"""Where a client looks for a daemon (hilgate.core.paths.client_runtime_dir): a runtime directory in a
directory anyone may write to (``/tmp/hilgate-UID``, or a variable's choice in /tmp) that belongs to
another user is a daemon anyone could fake: the client does not connect there (the daemon refuses
such a directory too, docs/security.md), or an application's frames and ``hilgate status`` would go
to whoever created the name first."""

from __future__ import annotations

import os
import socket

import pytest

from hilgate.core.paths import client_runtime_dir

STRANGER = 54321  # a uid that is not this user's (the test chowns to it: it needs root)


def _daemon_dir(parent: str, owner: int | None) -> tuple[str, socket.socket]:
    os.makedirs(parent, exist_ok=True)
    os.chmod(parent, 0o1777)  # like /tmp: anyone may create a name in it
    runtime = os.path.join(parent, "hilgate")
    os.mkdir(runtime, 0o755)
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(os.path.join(runtime, "control.sock"))
    server.listen(1)
    if owner is not None:
        os.chown(runtime, owner, owner)
    return runtime, server


@pytest.fixture
def env(monkeypatch):
    for name in ("HILGATE_RUNTIME_DIR", "RUNTIME_DIRECTORY", "XDG_RUNTIME_DIR"):
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


@pytest.mark.skipif(os.geteuid() != 0, reason="giving a directory to another user needs root")
def test_a_runtime_dir_another_user_created_in_a_shared_directory_is_not_trusted(tmp_path, env):
    runtime, server = _daemon_dir(str(tmp_path / "shared"), STRANGER)
    try:
        env.setenv("HILGATE_RUNTIME_DIR", runtime)
        try:
            chosen = client_runtime_dir()
        except OSError as exc:  # (nowhere else to go: refused in one line)
            assert runtime in str(exc) and f"uid {STRANGER}" in str(exc)
        else:
            assert chosen != runtime
    finally:
        server.close()


def test_a_runtime_dir_of_this_user_in_a_shared_directory_is_found(tmp_path, env):
    runtime, server = _daemon_dir(str(tmp_path / "shared"), None)
    try:
        env.setenv("HILGATE_RUNTIME_DIR", runtime)
        assert client_runtime_dir() == runtime
    finally:
        server.close()


@pytest.mark.skipif(os.geteuid() != 0, reason="giving a directory to another user needs root")
def test_an_explicit_runtime_dir_is_taken_as_given(tmp_path, env):
    runtime, server = _daemon_dir(str(tmp_path / "shared"), STRANGER)
    try:
        assert client_runtime_dir(runtime) == runtime  # --runtime-dir: the user said where
    finally:
        server.close()
