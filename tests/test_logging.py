"""Log lines under systemd's journal (issue 11 item 9): ``<N>`` syslog priorities, no timestamp, INFO.

systemd points ``$JOURNAL_STREAM`` (device:inode) at the stream it connected to the journal; here that
stream is a pipe whose device and inode the test puts in the variable, as systemd would."""

from __future__ import annotations

import os
import re
import selectors
import subprocess
import sys
import time

from daemon_kit import unique
from hilgate.gli.queues import unlink_queues

LOG_EVERY_LEVEL = """
import logging, sys
from hilgate.logsetup import setup_logging
setup_logging(int(sys.argv[1]), daemon=sys.argv[2] == "daemon")
log = logging.getLogger("hilgate.probe")
log.debug("a debug line")
log.info("an info line")
log.warning("a warning line")
log.error("an error line")
try:
    1 / 0
except ZeroDivisionError:
    log.exception("it failed")
"""

TIMESTAMP = re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d")


def run_logged(argv: list[str], journal: bool | str, env: dict | None = None, hang_guard: float = 120) -> tuple[int, str]:
    """Run ``argv`` with stderr on a pipe; ``journal``: True sets JOURNAL_STREAM to that pipe,
    a string sets it to that value, False removes it.  Returns (exit status, stderr)."""
    read_end, write_end = os.pipe()
    status = os.fstat(write_end)
    environment = {k: v for k, v in os.environ.items() if k not in ("JOURNAL_STREAM", "HILGATE_LOG_LEVEL")}
    if journal is True:
        environment["JOURNAL_STREAM"] = f"{status.st_dev}:{status.st_ino}"
    elif journal:
        environment["JOURNAL_STREAM"] = journal
    environment.update(env or {})
    process = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=write_end,
                               env=environment)
    os.close(write_end)
    chunks = []
    deadline = time.monotonic() + hang_guard  # only against a hang: never reached by a working run
    with selectors.DefaultSelector() as selector:
        selector.register(read_end, selectors.EVENT_READ)
        while True:
            if not selector.select(max(0.0, deadline - time.monotonic())):
                process.kill()
                raise AssertionError(f"{argv} still running after {hang_guard} s: {b''.join(chunks)!r}")
            data = os.read(read_end, 65536)
            if not data:
                break
            chunks.append(data)
    os.close(read_end)
    return process.wait(), b"".join(chunks).decode()


def probe(verbosity: int, mode: str, journal: bool | str, env: dict | None = None) -> list[str]:
    code, text = run_logged([sys.executable, "-c", LOG_EVERY_LEVEL, str(verbosity), mode], journal, env)
    assert code == 0, text
    return text.splitlines()


def test_journal_lines_carry_syslog_priorities_and_no_timestamp():
    lines = probe(0, "tool", journal=True)
    assert "<6>INFO hilgate.probe: an info line" in lines  # INFO by default under the journal
    assert "<4>WARNING hilgate.probe: a warning line" in lines
    assert "<3>ERROR hilgate.probe: an error line" in lines
    assert not any("debug" in line for line in lines)
    # a traceback is several lines; journald stores each as an entry: each keeps the error priority
    start = lines.index("<3>ERROR hilgate.probe: it failed")
    assert lines[start + 1] == "<3>Traceback (most recent call last):"
    assert lines[-1] == "<3>ZeroDivisionError: division by zero"
    assert all(re.match(r"<[0-7]>", line) for line in lines), lines
    assert not any(TIMESTAMP.search(line) for line in lines)  # journald stamps the lines itself


def test_journal_debug_with_vv_or_the_environment():
    assert "<7>DEBUG hilgate.probe: a debug line" in probe(2, "daemon", journal=True)
    assert "<7>DEBUG hilgate.probe: a debug line" in probe(0, "daemon", journal=True,
                                                          env={"HILGATE_LOG_LEVEL": "debug"})
    lines = probe(0, "daemon", journal=True, env={"HILGATE_LOG_LEVEL": "error"})
    assert lines[0] == "<3>ERROR hilgate.probe: an error line"


def test_inherited_journal_variable_of_another_stream_is_ignored():
    # a child started from the service whose stderr goes elsewhere (a file, a terminal) inherits the
    # variable; the stream is not the journal's, so no <N> prefixes there
    for value in ("0:0", "not-a-stream", ""):
        lines = probe(0, "tool", journal=value)
        assert lines[0] == "WARNING hilgate.probe: a warning line", (value, lines)
        assert not any(line.startswith("<") for line in lines)


def test_default_levels_outside_the_journal():
    tool = probe(0, "tool", journal=False)
    assert tool[0] == "WARNING hilgate.probe: a warning line"  # the one-shot tools stay quiet
    assert "INFO hilgate.probe: an info line" in probe(1, "tool", journal=False)
    daemon = probe(0, "daemon", journal=False)  # `hilgate run` in a terminal: INFO, with the time
    assert not any("debug line" in line for line in daemon)
    info = next(line for line in daemon if "an info line" in line)
    assert TIMESTAMP.match(info) and info.endswith(" INFO hilgate.probe: an info line"), info


def test_daemon_under_the_journal_logs_its_start_at_info(tmp_path):
    link = unique("log")
    scene = tmp_path / "scene.yaml"
    scene.write_text(f"""\
name: journal-test
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
links:
  {link}: {{vehicle: va, address: 1, bitrate_bps: 1000, packet: vl2b}}
""")
    try:
        code, text = run_logged([sys.executable, "-m", "hilgate", "run", str(scene), "--until", "0.2",
                                 "--runtime-dir", str(tmp_path / "rt"), "--no-status-line"], journal=True)
    finally:
        unlink_queues([link])
    assert code == 0, text
    lines = text.splitlines()
    assert lines and all(re.match(r"<[0-7]>", line) for line in lines), lines
    assert any(line.startswith("<6>INFO hilgate") for line in lines), lines  # the start-up line
    assert not any(TIMESTAMP.search(line) for line in lines), lines
