"""The command-line tools report what the daemon answered, and refuse bad arguments in one line."""


import pytest

from daemon_kit import hilgate, quick_scene, unique


def test_send_reports_a_frame_the_daemon_refuses_and_exits_1(daemon_of):
    a, b = unique("a"), unique("b")
    daemon = daemon_of(quick_scene("cli", a, b), [a, b])
    ok = hilgate("send", a, "--to", "2", "--runtime-dir", daemon.runtime, "hello")
    assert ok.returncode == 0, ok.stderr
    big = hilgate("send", a, "--to", "2", "--runtime-dir", daemon.runtime, "x" * 5000)
    assert big.returncode == 1
    assert "refused" in big.stderr and "Traceback" not in big.stderr
    lines = hilgate("send", a, "--runtime-dir", daemon.runtime, input="one\n" + "y" * 5000 + "\nthree\n")
    assert lines.returncode == 1 and lines.stderr.count("refused") == 1
    assert sum(daemon.link_status(a)["drop_causes"].values()) == 2  # and the daemon counted both


@pytest.mark.parametrize("args", [
    ("send", "x", "--to", "300", "hi"),
    ("send", "x", "--to", "two", "hi"),
    ("send", "x", "--tcp", "notaport", "hi"),
    ("listen", "x", "--tcp", "host:99999"),
    ("run", "--tcp", "nope"),
])
def test_bad_arguments_are_one_line_and_exit_2(args):
    result = hilgate(*args)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert len([line for line in result.stderr.splitlines() if "error" in line]) == 1
