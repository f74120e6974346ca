"""`make test` must pass whether or not the mqueue filesystem is mounted (containers and many machines do
not mount it at /dev/mqueue; the kernel then lists no queue, and hilgate learns about a scene's queues
through the queue API alone).  The suite runs in whichever state this machine is in; this test runs the
queue tests once more in the other state, in a private mount namespace (``unshare -m``): where the
filesystem is mounted it is unmounted there, where it is not it is mounted there.  Nothing changes
outside that namespace.  A machine that allows no such namespace (no unshare, no CAP_SYS_ADMIN) skips it,
saying why."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
QUEUE_TESTS = ["tests/test_gli_endpoints.py"]
MQUEUE = "/dev/mqueue"
FLIPPED = "HILGATE_TEST_MQUEUE_FLIPPED"


def _flip(tmp_path) -> tuple[str, dict[str, str], bool]:
    """The shell command that flips the mount in the namespace, the environment the tests get there,
    and whether the filesystem is mounted there afterwards."""
    if os.path.ismount(MQUEUE):
        return f"umount {MQUEUE}", {}, False
    if os.path.isdir(MQUEUE):
        return f"mount -t mqueue mqueue {MQUEUE}", {}, True
    place = tmp_path / "mqueue"  # no /dev/mqueue to mount on: mount it elsewhere and say where
    place.mkdir()
    return f"mount -t mqueue mqueue {place}", {"HILGATE_MQUEUE_DIR": str(place)}, True


@pytest.mark.skipif(bool(os.environ.get(FLIPPED)), reason="this run is the flipped one")
def test_queue_tests_pass_with_the_mqueue_filesystem_in_the_other_state(tmp_path):
    unshare = shutil.which("unshare")
    if unshare is None:
        pytest.skip("no unshare(1) here to make a private mount namespace")
    flip, env, mounted_there = _flip(tmp_path)
    check = (f'"$0" -c "import sys; from hilgate.gli.limits import list_queues; '
             f'sys.exit(0 if (list_queues() is not None) == {mounted_there} else 3)"')
    probe = subprocess.run([unshare, "-m", "sh", "-c", f"{flip} && {check}", sys.executable], cwd=REPO,
                           env=dict(os.environ, **env), capture_output=True, text=True, timeout=120)
    if probe.returncode != 0:
        pytest.skip(f"cannot flip the mqueue filesystem in a private mount namespace here "
                    f"({(probe.stderr.strip() or f'exit {probe.returncode}').splitlines()[-1]})")
    result = subprocess.run(
        [unshare, "-m", "sh", "-c", f'{flip} && exec "$0" -m pytest -q -p no:cacheprovider "$@"', sys.executable,
         *QUEUE_TESTS], cwd=REPO, env=dict(os.environ, **env, **{FLIPPED: "1"}), capture_output=True, text=True,
        timeout=1800)  # a hang guard: the queue tests take seconds
    assert result.returncode == 0, f"mqueue {'mounted' if mounted_there else 'not mounted'}:\n{result.stdout[-4000:]}"
    assert " passed" in result.stdout and " skipped" not in result.stdout.splitlines()[-1]
