import os
import sys

import pytest

# Tests import small helpers from this folder (daemon_kit, netkit) without making tests a package.
sys.path.insert(0, os.path.dirname(__file__))

from daemon_kit import Daemon  # noqa: E402


@pytest.fixture
def daemon_of(tmp_path):
    """Start daemons for a test: ``daemon_of(scene_text, links, *args, **options)`` runs one in a directory
    of its own under ``tmp_path``, waits for its READY=1, and closes it (and unlinks its queues) after
    the test, whatever happened."""
    started = []

    def start(scene_text: str, links: list[str], *args: str, **options) -> Daemon:
        directory = tmp_path / f"daemon{len(started)}"
        directory.mkdir()
        daemon = Daemon(directory, scene_text, links, *args, **options)
        started.append(daemon)
        daemon.wait_for("READY=1")
        return daemon

    yield start
    for daemon in started:
        daemon.close()
