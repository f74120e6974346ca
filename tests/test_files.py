"""What hilgate writes on the file system (issue 23 item 5, :mod:`hilgate.core.outputs`).

A scene writes its trace file and its emulated modems' pty links, nothing else: a pty path where
something other than a pty link is, or a trace file that is not one of hilgate's, is refused when the
scene loads (``FILE:LINE``) and left as it was; a pty link is removed at stop only if it is still the
daemon's own; traces and summaries are created 0640 for the daemon's group.
"""

import os
import stat
import subprocess

import pytest

from daemon_kit import Daemon, hilgate, unique
from hilgate.core.outputs import OutputError, open_output, output_problem, pty_link_problem
from hilgate.drivers.emulators import PtyHost
from hilgate.scene import SceneError, load_scene_text

GROUP = 54322


def emulator_scene(link: str, pty) -> str:
    return f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links:
  {link}: {{vehicle: v, address: 4, emulate: {{protocol: evologics, pty: {pty}}}}}
"""


def one_line(result: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.startswith("hilgate: ")]
    assert len(lines) == 1, result.stderr
    return lines[0]


def make_file(path):
    path.write_text("precious\n")


def make_link(path):
    (path.parent / "target").write_text("precious\n")
    path.symlink_to(path.parent / "target")


def make_dangling_link(path):
    path.symlink_to("/nonexistent/zoneinfo")


def make_directory(path):
    path.mkdir()


def make_fifo(path):
    os.mkfifo(path)


def trace_scene(link: str, trace) -> str:
    return f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links: {{{link}: {{vehicle: v, address: 4}}}}
trace: {{file: {trace}}}
"""


PTY = ("tty", emulator_scene, "links.x.emulate.pty")
TRACE = ("trace.jsonl", trace_scene, "trace.file")


@pytest.mark.parametrize("where,make,words", [
    (PTY, make_file, "is not a pty link (a regular file)"),
    (PTY, make_link, "is a link to"),               # pty: /etc/localtime removed a system file's link before
    (PTY, make_dangling_link, "not to a pty"),
    (PTY, make_directory, "is not a pty link (a directory)"),
    (PTY, make_fifo, "is not a pty link (a FIFO)"),
    (TRACE, make_file, "holds something that is not a hilgate trace"),
    (TRACE, make_link, "is a symbolic link, not a regular file"),
    (TRACE, make_directory, "is a directory, not a regular file"),
    (TRACE, make_fifo, "is a FIFO, not a regular file"),
])
def test_a_path_where_something_else_is_is_refused_when_the_scene_loads_and_left_untouched(tmp_path, where, make,
                                                                                          words):
    """A pty's path that is no pty link of hilgate's, a trace file that is no trace: the scene does not load,
    its error names the file, line, key and path, and what is there is left as it was."""
    name, scene, key = where
    path = tmp_path / name
    make(path)
    before = os.lstat(path)
    with pytest.raises(SceneError) as caught:
        load_scene_text(scene("x", path), str(tmp_path / "scene.yaml"))
    message = str(caught.value)
    assert message.startswith(f"{tmp_path / 'scene.yaml'}:4: {key}: {path}") and words in message
    after = os.lstat(path)
    assert (after.st_ino, after.st_mode) == (before.st_ino, before.st_mode)


def test_hilgate_emulate_refuses_the_path_of_a_file_in_one_line(tmp_path):
    victim = tmp_path / "localtime"
    make_link(victim)
    (tmp_path / "scene.yaml").write_text(emulator_scene("x", tmp_path / "tty"))
    result = hilgate("emulate", "evologics", str(tmp_path / "scene.yaml"), "--link", "x", "--pty", str(victim),
                     "--runtime-dir", str(tmp_path / "rt"))
    assert result.returncode == 2 and "is a link to" in one_line(result)
    assert victim.is_symlink() and victim.read_text() == "precious\n"


def test_the_pty_host_checks_again_when_it_opens(tmp_path):
    """Between the load and the open the path may have been taken: the emulator refuses it then too."""
    path = tmp_path / "tty"
    make_file(path)
    with pytest.raises(OutputError, match="is not a pty link"):
        PtyHost(str(path), object(), None, "x")  # refused before it touches the scheduler
    assert path.read_text() == "precious\n"


def test_a_stale_pty_link_is_replaced_and_the_daemons_own_link_removed_at_stop(tmp_path, daemon_of):
    link = unique("pt")
    stale = tmp_path / "ttyEVO"
    stale.symlink_to("/dev/pts/987654")  # what a daemon killed with SIGKILL leaves
    assert pty_link_problem(str(stale)) is None
    daemon = daemon_of(emulator_scene(link, stale), [link])
    target = os.readlink(stale)
    assert target.startswith("/dev/pts/") and target != "/dev/pts/987654"
    daemon.stop()
    assert not os.path.lexists(stale)  # its own link, removed


def test_a_link_that_replaced_the_daemons_own_is_not_removed_at_stop(tmp_path, daemon_of):
    link = unique("pt")
    path = tmp_path / "ttyEVO"
    daemon = daemon_of(emulator_scene(link, path), [link])
    os.unlink(path)
    path.symlink_to(tmp_path / "someone-elses")  # another program's link now
    daemon.stop()
    assert os.readlink(path) == str(tmp_path / "someone-elses")


def test_the_command_lines_trace_and_summary_follow_the_same_rules(tmp_path):
    scene = tmp_path / "scene.yaml"
    scene.write_text(trace_scene("x", tmp_path / "scene-trace.jsonl").replace("trace: {file", "#"))
    victim = tmp_path / "passwd"
    make_file(victim)
    for option in ("--trace", "--summary"):
        result = hilgate("sim", str(scene), "--until", "1", "-q", option, str(victim))
        assert result.returncode == 1 and "holds something that is not a hilgate" in one_line(result)
        assert victim.read_text() == "precious\n"
    link = unique("tr")
    (tmp_path / "d").mkdir()
    daemon = Daemon(tmp_path / "d", trace_scene(link, tmp_path / "d" / "t.jsonl").replace("trace: {file", "#"),
                    [link], "--summary", str(victim))
    code = daemon.process.wait(60)
    output = daemon.output()
    daemon.close()
    assert code == 1 and "Traceback" not in output and "not a hilgate summary" in output
    assert victim.read_text() == "precious\n"


def test_an_existing_trace_is_appended_to_and_a_summary_replaced(tmp_path):
    trace, summary = tmp_path / "t.jsonl", tmp_path / "s.json"
    with open_output(str(trace), "trace", append=True) as handle:
        handle.write('{"t": 0.0, "ev": "run"}\n')
    with open_output(str(trace), "trace", append=True) as handle:
        handle.write('{"t": 1.0, "ev": "run"}\n')
    assert trace.read_text().count('"run"') == 2
    for text in ('{"a": 1}\n', '{"b": 2}\n'):
        with open_output(str(summary), "summary", append=False) as handle:
            handle.write(text)
    assert summary.read_text() == '{"b": 2}\n'
    assert output_problem(str(tmp_path / "new.jsonl"), "trace") is None


def test_traces_and_summaries_are_created_0640_for_the_daemons_group(tmp_path):
    """0640 whatever the umask (the issue found 0644 under the usual 022); the group is --group's."""
    link = unique("tr")
    group = ["--group", str(GROUP)] if os.geteuid() == 0 else []
    old = os.umask(0o022)
    try:
        daemon = Daemon(tmp_path, trace_scene(link, tmp_path / "scene-trace.jsonl").replace("trace: {file", "#"),
                        [link], *group)
    finally:
        os.umask(old)
    try:
        daemon.wait_for("READY=1")
        daemon.stop()
        for path in (daemon.trace, daemon.summary):
            info = os.stat(path)
            assert stat.S_IMODE(info.st_mode) == 0o640, path
            if group:
                assert info.st_gid == GROUP, path
    finally:
        daemon.close()
    old = os.umask(0o022)
    try:
        scene = tmp_path / "sim.yaml"
        scene.write_text(trace_scene("x", tmp_path / "sim-trace.jsonl"))
        result = hilgate("sim", str(scene), "--until", "1", "-q", "--summary", str(tmp_path / "sim-summary.json"))
    finally:
        os.umask(old)
    assert result.returncode == 0, result.stderr
    for name in ("sim-trace.jsonl", "sim-summary.json"):
        assert stat.S_IMODE(os.stat(tmp_path / name).st_mode) == 0o640, name


# -- issue 37 item 6: another user's link in the path, another user's file -------------------------------

OUTSIDER = (65534, 65534)


def refused_run(tmp_path, link: str, *args: str) -> str:
    """The one-line error of a daemon that must not start with ``args``."""
    daemon = Daemon(tmp_path, trace_scene(link, tmp_path / "scene-trace.jsonl").replace("trace: {file", "#"),
                    [link], *args)
    code = daemon.process.wait(60)
    output = daemon.output()
    daemon.close()
    assert code == 1 and "Traceback" not in output, output
    return output


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root: another user's directory and link (chown)")
def test_a_directory_in_the_path_that_is_another_users_link_is_refused(tmp_path):
    """Root followed another user's symlink ``logs -> their 0700 directory`` and wrote the trace there
    (``--trace logs/t.jsonl``): that user chose where root writes.  A link in the path must be root's
    or the daemon user's own; the file is opened through the directories walked one by one."""
    theirs = tmp_path / "theirs"
    theirs.mkdir(mode=0o700)
    os.chown(theirs, *OUTSIDER)
    logs = tmp_path / "logs"
    logs.symlink_to(theirs)
    os.lchown(logs, *OUTSIDER)
    scene = tmp_path / "scene.yaml"
    scene.write_text(trace_scene("x", tmp_path / "scene-trace.jsonl").replace("trace: {file", "#"))
    for option in ("--trace", "--summary"):
        result = hilgate("sim", str(scene), "--until", "1", "-q", option, str(logs / "out.json"))
        assert result.returncode == 1 and f"{logs} is a symbolic link of uid 65534" in one_line(result)
    nested = logs / "deeper" / "t.jsonl"  # the link anywhere in the path, not only the last directory
    result = hilgate("sim", str(scene), "--until", "1", "-q", "--trace", str(nested))
    assert result.returncode == 1 and "symbolic link of uid 65534" in one_line(result)
    in_scene = tmp_path / "in-scene.yaml"
    in_scene.write_text(trace_scene("x", logs / "t.jsonl"))
    result = hilgate("check", str(in_scene))
    assert result.returncode == 2 and "trace.file" in result.stderr and "symbolic link of uid 65534" in result.stderr
    in_scene.write_text(emulator_scene("x", logs / "tty"))  # an emulated modem's pty link: the same rule
    result = hilgate("check", str(in_scene))
    assert result.returncode == 2 and "emulate.pty" in result.stderr and "symbolic link of uid 65534" in result.stderr
    with pytest.raises(OutputError, match="symbolic link of uid 65534"):
        PtyHost(str(logs / "tty"), None, None, "x")
    for option in ("--trace", "--summary"):
        (tmp_path / option).mkdir()
        output = refused_run(tmp_path / option, unique("tr"), option, str(logs / "run.jsonl"))
        assert "symbolic link of uid 65534" in output
    assert os.listdir(theirs) == []
    # a link of the daemon's own user (or root's: /var/run -> /run) is the user's choice, and followed
    mine = tmp_path / "mine"
    mine.mkdir()
    own = tmp_path / "own"
    own.symlink_to(mine)
    result = hilgate("sim", str(scene), "--until", "1", "-q", "--trace", str(own / "t.jsonl"))
    assert result.returncode == 0, result.stderr
    assert (mine / "t.jsonl").read_text().startswith('{"t":')


def test_an_existing_output_file_others_may_write_is_refused(tmp_path):
    """An empty 0666 trace made beforehand was accepted and written to: whoever could write it could
    read the trace, or truncate it under the daemon."""
    scene = tmp_path / "scene.yaml"
    scene.write_text(trace_scene("x", tmp_path / "scene-trace.jsonl").replace("trace: {file", "#"))
    shared = tmp_path / "shared.jsonl"
    shared.write_bytes(b"")
    os.chmod(shared, 0o666)
    for option in ("--trace", "--summary"):
        result = hilgate("sim", str(scene), "--until", "1", "-q", option, str(shared))
        assert result.returncode == 1 and "writable by others (mode 0666)" in one_line(result)
    (tmp_path / "d").mkdir()
    assert "writable by others" in refused_run(tmp_path / "d", unique("tr"), "--trace", str(shared))
    assert shared.read_bytes() == b""
    if os.geteuid() == 0:  # another user's, however closed
        theirs = tmp_path / "theirs.jsonl"
        theirs.write_bytes(b"")
        os.chown(theirs, *OUTSIDER)
        for mode in (0o666, 0o600):
            os.chmod(theirs, mode)
            result = hilgate("sim", str(scene), "--until", "1", "-q", "--trace", str(theirs))
            assert result.returncode == 1 and "belongs to uid 65534" in one_line(result)
        (tmp_path / "e").mkdir()
        assert "belongs to uid 65534" in refused_run(tmp_path / "e", unique("tr"), "--summary", str(theirs))
        assert theirs.read_bytes() == b""
