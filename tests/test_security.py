"""Who may talk to the daemon (issue: closed to other users).

The daemon's runtime directory is 0750, its sockets and queues 0660 for its group; things someone
else created first are refused in one line; a link id is served by one daemon per host.  The test
that crosses users runs the daemon as root and its clients as two other uids (one in the daemon's
group, one not); without root it is skipped.
"""

import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import textwrap

import posix_ipc
import pytest

from daemon_kit import Daemon, unique
from hilgate.daemon.access import AccessError, LinkLock, lock_directory, prepare_lock_directory, prepare_private_dir

OUTSIDER = (65534, 65534)
MEMBER = (65533, 65533)
GROUP = 54321


def scene(*links: str) -> str:
    rows = "\n".join(f"  {link}: {{vehicle: v{i}, address: {i + 1}, packet: vl2b}}" for i, link in enumerate(links))
    vehicles = "\n".join(f"  v{i}: {{pose: {{static: [{i}, 0, 0]}}}}" for i in range(len(links)))
    return f"name: security\nchannels: {{ac: {{speed_mps: 1500}}}}\nvehicles:\n{vehicles}\nlinks:\n{rows}\ntrace: {{poses_s: 0}}\n"


def failure(daemon: Daemon) -> tuple[int, str]:
    code = daemon.process.wait(60)
    return code, daemon.output()


def test_runtime_directory_and_sockets_are_for_the_daemons_user_and_group(daemon_of):
    a = unique("a")
    daemon = daemon_of(scene(a), [a])
    assert stat.S_IMODE(os.stat(daemon.runtime).st_mode) == 0o750
    assert stat.S_IMODE(os.stat(os.path.join(daemon.runtime, "gli")).st_mode) == 0o750
    for path in ("control.sock", f"gli/{a}.sock"):
        assert stat.S_IMODE(os.stat(os.path.join(daemon.runtime, path)).st_mode) == 0o660, path
    for name in (f"/{a}_tx_dlnk_phy", f"/{a}_rx_dlnk_phy"):
        queue = posix_ipc.MessageQueue(name)
        assert stat.S_IMODE(os.fstat(queue.mqd).st_mode) == 0o660, name
        queue.close()


CLIENT = textwrap.dedent("""\
    import ctypes, ctypes.util, errno, json, os, socket, sys
    runtime, link = sys.argv[1], sys.argv[2]
    result = {}
    for what, path in (("control", os.path.join(runtime, "control.sock")), ("gli", os.path.join(runtime, "gli", link + ".sock"))):
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.settimeout(10)
        try:
            s.connect(path)
            result[what] = "ok" if s.recv(1) else "closed"
        except OSError as exc:
            result[what] = type(exc).__name__
        s.close()
    rt = ctypes.CDLL(ctypes.util.find_library("rt"), use_errno=True)
    for direction in ("tx", "rx"):
        fd = rt.mq_open(("/%s_%s_dlnk_phy" % (link, direction)).encode(), os.O_RDWR)
        result[direction] = "ok" if fd >= 0 else errno.errorcode[ctypes.get_errno()]
        if fd >= 0:
            rt.mq_close(fd)
    print(json.dumps(result))
""")


def python_for(uid: int, gid: int) -> str | None:
    """A Python interpreter that another user may run (the test's own may live under /root)."""
    for candidate in (sys.executable, "/usr/bin/python3", "/usr/local/bin/python3"):
        try:
            if subprocess.run([candidate, "-c", "pass"], user=uid, group=gid, capture_output=True,
                              timeout=60).returncode == 0:
                return candidate
        except OSError:
            continue
    return None


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run clients as other users")
def test_other_users_cannot_reach_the_daemon_but_members_of_its_group_can(tmp_path):
    base = tempfile.mkdtemp(prefix="hilgate-sec-", dir="/tmp")
    os.chmod(base, 0o711)  # others may traverse to the runtime directory, not list it
    a = unique("a")
    daemon = Daemon(tmp_path, scene(a), [a], "--group", str(GROUP), runtime=os.path.join(base, "rt"))
    try:
        daemon.wait_for("READY=1")

        python = python_for(*OUTSIDER)
        if python is None:
            pytest.skip("no Python interpreter that another user may run")

        def attempt(uid, gid, groups=()):
            out = subprocess.run([python, "-c", CLIENT, daemon.runtime, a], capture_output=True, text=True,
                                 timeout=60, user=uid, group=gid, extra_groups=list(groups),
                                 env={**os.environ, "HOME": "/"})
            assert out.returncode == 0, out.stderr
            return json.loads(out.stdout)

        assert attempt(*OUTSIDER) == {"control": "PermissionError", "gli": "PermissionError",
                                      "tx": "EACCES", "rx": "EACCES"}
        assert attempt(*MEMBER, groups=[GROUP]) == {"control": "ok", "gli": "ok", "tx": "ok", "rx": "ok"}
    finally:
        daemon.close()
        shutil.rmtree(base, ignore_errors=True)


def one_line_error(output: str) -> str:
    lines = [line for line in output.splitlines() if line.startswith("hilgate: ")]
    assert "Traceback" not in output, output
    assert len(lines) == 1, output
    return lines[0]


def test_a_queue_made_too_small_by_someone_first_is_refused_in_one_line(tmp_path):
    a = unique("a")
    squat = posix_ipc.MessageQueue(f"/{a}_rx_dlnk_phy", posix_ipc.O_CREX, mode=0o600, max_messages=1,
                                   max_message_size=1)
    try:
        daemon = Daemon(tmp_path, scene(a), [])  # its queues are the test's: the kit must not unlink them
        code, output = failure(daemon)
        line = one_line_error(output)
        assert code == 1
        assert f"/{a}_rx_dlnk_phy" in line and "at most 1 bytes" in line and "hilgate queues" in line
        assert "ulimit" not in line  # the budget hint only when the budget is the problem
        daemon.close()
        with pytest.raises(posix_ipc.ExistentialError):  # the tx queue it had made is removed again
            posix_ipc.MessageQueue(f"/{a}_tx_dlnk_phy")
    finally:
        squat.close()
        squat.unlink()


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to create a queue as another user")
def test_a_queue_created_first_by_another_user_is_refused(tmp_path):
    a = unique("a")
    name = f"/{a}_rx_dlnk_phy"
    python = python_for(*OUTSIDER)
    if python is None:
        pytest.skip("no Python interpreter that another user may run")
    made = subprocess.run([python, "-c", "import ctypes, ctypes.util, os, sys;"
                           "rt = ctypes.CDLL(ctypes.util.find_library('rt'), use_errno=True);"
                           "sys.exit(0 if rt.mq_open(sys.argv[1].encode(), os.O_CREAT | os.O_RDWR, 0o666, None) >= 0 else 1)",
                           name], user=OUTSIDER[0], group=OUTSIDER[1], timeout=60)
    if made.returncode != 0:
        pytest.skip("could not create a queue as another user")
    try:
        daemon = Daemon(tmp_path, scene(a), [])
        code, output = failure(daemon)
        line = one_line_error(output)
        assert code == 1 and name in line and "uid 65534" in line and "hilgate queues" in line
        daemon.close()
    finally:
        posix_ipc.unlink_message_queue(name)
        for leftover in (f"/{a}_tx_dlnk_phy",):  # the daemon may have created the other one before refusing
            try:
                posix_ipc.unlink_message_queue(leftover)
            except posix_ipc.ExistentialError:
                pass


def test_a_link_is_served_by_one_daemon_per_host(tmp_path):
    a, b = unique("a"), unique("b")
    first = Daemon(tmp_path / "one", scene(a, b), [a, b]) if (tmp_path / "one").mkdir() is None else None
    try:
        first.wait_for("READY=1")
        (tmp_path / "two").mkdir()
        second = Daemon(tmp_path / "two", scene(b), [])  # another runtime directory, one link in common
        code, output = failure(second)
        line = one_line_error(output)
        assert code == 1 and f"link {b}" in line and f"process {first.process.pid}" in line
        second.close()
        assert first.status()["class"] == "STATUS"  # the first one is undisturbed
    finally:
        first.close()


def test_a_runtime_directory_that_is_a_symlink_or_someone_elses_is_refused(tmp_path):
    target = tmp_path / "elsewhere"
    target.mkdir()
    link = tmp_path / "rt-link"
    link.symlink_to(target)
    with pytest.raises(AccessError, match="not a directory"):
        prepare_private_dir(str(link))
    if os.geteuid() == 0:
        theirs = tmp_path / "theirs"
        theirs.mkdir(mode=0o777)
        os.chown(theirs, *OUTSIDER)
        with pytest.raises(AccessError, match="belongs to"):
            prepare_private_dir(str(theirs))
        their_link = tmp_path / "their-link"  # another user's link on the way to it (issue 37 item 6)
        their_link.symlink_to(theirs)
        os.lchown(their_link, *OUTSIDER)
        with pytest.raises(AccessError, match="symbolic link of uid 65534"):
            prepare_private_dir(str(their_link / "rt"))
        assert os.listdir(theirs) == []
    mine = tmp_path / "mine"
    mine.mkdir(mode=0o777)
    os.chmod(mine, 0o777)
    prepare_private_dir(str(mine))  # ours: made private
    assert stat.S_IMODE(os.stat(mine).st_mode) == 0o750
    a = unique("a")
    daemon = Daemon(tmp_path, scene(a), [a], runtime=str(link))
    code, output = failure(daemon)
    assert code == 1 and "not a directory" in one_line_error(output)
    daemon.close()


def test_link_lock_names_its_holder(tmp_path):
    name = unique("lock")
    directory = str(tmp_path / "locks")
    prepare_lock_directory(directory)
    assert stat.S_IMODE(os.stat(directory).st_mode) == 0o700
    held = LinkLock(name, directory)
    try:
        with pytest.raises(AccessError, match=f"process {os.getpid()}"):
            LinkLock(name, directory)
    finally:
        held.release()
    LinkLock(name, directory).release()  # free again once released
    assert os.listdir(directory) == []
    stale = LinkLock(name, directory)  # a holder that died leaves its file, unlocked: taken again
    os.close(stale.fd)
    LinkLock(name, directory).release()


SQUATTER = textwrap.dedent("""\
    # Takes a link's name first, as the lock before issue 37 was (an abstract Unix socket), and holds it
    # until its stdin closes.
    import socket, sys
    held = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    held.bind(b"\\0hilgate/link/" + sys.argv[1].encode())
    held.listen(1)
    print("held", flush=True)
    sys.stdin.read()
""")


def test_another_user_cannot_keep_a_link_from_starting(tmp_path):
    """Issue 37 item 6: the link's lock was an abstract Unix socket named after its id, which any local
    user could bind first; the daemon was refused ("already served by process N of nobody").  Now the
    lock is a file in a directory only the daemon's user may enter."""
    a = unique("a")
    who = {"user": OUTSIDER[0], "group": OUTSIDER[1]} if os.geteuid() == 0 else {}
    python = python_for(*OUTSIDER) if who else sys.executable
    if python is None:
        pytest.skip("no Python interpreter that another user may run")
    squatter = subprocess.Popen([python, "-c", SQUATTER, a], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                text=True, **who)
    try:
        assert squatter.stdout.readline().strip() == "held"
        daemon = Daemon(tmp_path, scene(a), [a])
        try:
            daemon.wait_for("READY=1")
            assert [link["id"] for link in daemon.status()["links"]] == [a]
            directory = lock_directory(daemon.runtime)
            info = os.stat(directory)
            assert stat.S_IMODE(info.st_mode) == 0o700 and info.st_uid == os.geteuid()
            if who:  # the lock itself: another user can neither open it nor make a name beside it
                probe = subprocess.run([python, "-c", "import sys; open(sys.argv[1]).close()",
                                        os.path.join(directory, f"{a}.lock")], capture_output=True, text=True,
                                       timeout=60, **who)
                assert probe.returncode == 1 and "PermissionError" in probe.stderr
        finally:
            daemon.close()
    finally:
        squatter.stdin.close()
        squatter.wait(60)


def test_an_unknown_group_is_a_configuration_error(tmp_path):
    a = unique("a")
    daemon = Daemon(tmp_path, scene(a), [], "--group", "no-such-group-" + a)
    code, output = failure(daemon)
    assert code == 2 and "no group" in one_line_error(output)
    daemon.close()
