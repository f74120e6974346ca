"""A link's choice of GLI endpoints (``gli: [mq, socket]``) and the limits POSIX queues run into.

The daemon runs in a subprocess with real queues and sockets; the budget check is tested with given
limits (the system-wide ``queues_max`` is shared by the machine and cannot be lowered by a test) and
with a real, lowered RLIMIT_MSGQUEUE in a child process."""

from __future__ import annotations

import errno
import os
import resource
import subprocess
import sys

import pytest

from hilgate.client import Link
from hilgate.gli.limits import Limits, budget_problems, describe, open_failure, probe_queue, queue_names, read_limits, scene_need
from hilgate.scene import SceneError
from hilgate.scene.load import load_scene
from daemon_kit import unique


def scene(links: dict[str, str]) -> str:
    lines = "\n".join(f"  {link}: {{vehicle: va, address: {i + 1}, bitrate_bps: 1e6{extra}}}"
                      for i, (link, extra) in enumerate(links.items()))
    return f"""\
name: gli-endpoints
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
links:
{lines}
"""


def queue_exists(link: str) -> list[bool]:
    """Asked of the queue API, not of /dev/mqueue: the mqueue filesystem is not mounted everywhere."""
    return [probe_queue(name) is not None for name in queue_names(link)]


def test_socket_only_links_create_no_queues_and_still_carry_frames(daemon_of):
    a, b, both = unique("so"), unique("so"), unique("mq")
    daemon = daemon_of(scene({a: ", gli: [socket]", b: ", gli: socket", both: ""}), [a, b, both])
    assert queue_exists(a) == [False, False]
    assert queue_exists(b) == [False, False]
    assert queue_exists(both) == [True, True]
    assert all(os.path.exists(os.path.join(daemon.runtime, "gli", f"{l}.sock")) for l in (a, b, both))
    with Link.open(b, runtime_dir=daemon.runtime) as receiver, Link.open(a, runtime_dir=daemon.runtime) as sender:
        sender.send(b"no queue", dst=2)
        message = receiver.recv(timeout=10)
    assert message is not None and (message.data, message.src, message.dst) == (b"no queue", 1, 2)
    assert queue_exists(a) == [False, False]


def test_queue_only_link_opens_no_socket_and_a_reload_adds_it(daemon_of):
    link = unique("mo")
    daemon = daemon_of(scene({link: ", gli: [mq]"}), [link])
    sock = os.path.join(daemon.runtime, "gli", f"{link}.sock")
    assert queue_exists(link) == [True, True]
    assert not os.path.exists(sock)
    daemon.reload(scene({link: ", gli: [mq, socket]"}))
    assert os.path.exists(sock)
    daemon.reload(scene({link: ", gli: [socket]"}))
    assert os.path.exists(sock)
    assert daemon.process.poll() is None


def test_bad_gli_is_refused_with_file_line_and_key(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(scene({"x1": ", gli: [socket, tcp]"}))
    with pytest.raises(SceneError) as caught:
        load_scene(str(path))
    assert "links.x1.gli[1]" in str(caught.value) and "scene.yaml:6" in str(caught.value)
    path.write_text(scene({"x1": ", gli: [socket, socket]"}))
    with pytest.raises(SceneError, match="given twice"):
        load_scene(str(path))


# -- the budget ------------------------------------------------------------------------------------

def limits(**changes) -> Limits:
    values = dict(user_bytes=819_200, user_bytes_used=0, queues_max=256, queues_existing=frozenset(),
                  descriptors=20_000)
    values.update(changes)
    return Limits(**values)


def links(n: int, gli=("mq", "socket"), packet="simple:20"):
    return [(f"l{i}", gli, packet) for i in range(n)]


def test_budget_names_queues_max_when_the_system_wide_count_is_the_limit():
    # simple:20 queues cost 10 × (1 + 20 + 12 + 96) = 1 290 bytes: 200 links fit in ulimit -q, not in 256 queues
    need = scene_need(links(200), limits())
    assert (need.new_queues, need.queue_bytes) == (400, 400 * 1290)
    problems = budget_problems(need, limits())
    assert len(problems) == 1 and problems[0].startswith("system-wide queue count fs.mqueue.queues_max")
    existing = frozenset(f"other{i}" for i in range(251))
    problems = budget_problems(scene_need(links(3), limits(queues_existing=existing)), limits(queues_existing=existing))
    assert len(problems) == 1 and "queues_max" in problems[0] and "6 new queues and 251 existing" in problems[0]


def test_budget_names_the_per_user_budget_when_bytes_are_the_limit():
    # vl1b queues cost 10 × (1 + 271 + 96) = 3 680 bytes: 819 200 bytes hold 222 queues, 111 links (where the
    # issue's daemon stopped); 112 links need 824 320
    assert scene_need(links(111, packet="vl1b"), limits()).queue_bytes == 816_960
    assert budget_problems(scene_need(links(111, packet="vl1b"), limits(queues_max=1000)), limits(queues_max=1000)) == []
    need = scene_need(links(112, packet="vl1b"), limits(queues_max=1000))
    problems = budget_problems(need, limits(queues_max=1000))
    assert len(problems) == 1 and problems[0].startswith("per-user POSIX queue budget RLIMIT_MSGQUEUE (ulimit -q)")
    assert budget_problems(need, limits(queues_max=1000, user_bytes=None)) == []


def test_budget_names_the_descriptor_limit():
    need = scene_need(links(100), limits(user_bytes=None, queues_max=None))
    assert need.descriptors == 64 + 300
    problems = budget_problems(need, limits(user_bytes=None, queues_max=None, descriptors=256))
    assert len(problems) == 1 and problems[0].startswith("open files RLIMIT_NOFILE (ulimit -n)")


def test_socket_only_links_need_no_queue_budget():
    tiny = limits(user_bytes=1, queues_max=0, queues_existing=frozenset({"x"}))
    need = scene_need(links(500, gli=("socket",)), tiny)
    assert (need.mq_links, need.new_queues, need.queue_bytes) == (0, 0, 0)
    assert budget_problems(need, tiny) == []


def test_existing_queues_are_reused_not_counted_again():
    existing = frozenset({"l0_tx_dlnk_phy", "l0_rx_dlnk_phy"})
    assert scene_need(links(2), limits(queues_existing=existing)).new_queues == 2


def test_open_failure_names_the_limit():
    assert "fs.mqueue.queues_max" in open_failure("/q", OSError(errno.ENOSPC, "No space left on device"))
    assert "ulimit -q does not help" in open_failure("/q", OSError(errno.ENOSPC, "No space left on device"))
    assert "RLIMIT_MSGQUEUE" in open_failure("/q", OSError("This process already has the maximum number of files open"))


CHILD = """
import resource, sys
resource.setrlimit(resource.RLIMIT_MSGQUEUE, (4096, 4096))
from hilgate.gli.queues import QueueError, open_queue
try:
    open_queue(sys.argv[1], 2067, full_size=False)
except QueueError as exc:
    print(exc)
"""


def test_a_real_exhausted_user_budget_names_ulimit_q():
    name = "/" + unique("bq")
    out = subprocess.run([sys.executable, "-c", CHILD, name], capture_output=True, text=True, timeout=60).stdout
    assert "RLIMIT_MSGQUEUE, ulimit -q, now 4096 bytes" in out and "queues_max" not in out


def _low_queue_budget() -> None:
    resource.setrlimit(resource.RLIMIT_MSGQUEUE, (10_000, 10_000))


def test_check_reports_the_budget_and_the_limit_a_scene_exceeds(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(scene({unique("ck"): ", packet: vl1b", unique("ck"): ", packet: vl1b",
                           unique("ck"): ", packet: vl1b, gli: [socket]"}))
    result = subprocess.run([sys.executable, "-m", "hilgate", "check", str(path)], capture_output=True, text=True,
                            timeout=60, preexec_fn=_low_queue_budget)
    assert result.returncode == 0, result.stderr
    assert "GLI endpoints: 2 of 3 links with POSIX queues: 4 new queues of 272 bytes × 10, 14720 bytes" in result.stdout
    warnings = [line for line in result.stdout.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and warnings[0].startswith("warning: the scene exceeds the per-user POSIX queue "
                                                         "budget RLIMIT_MSGQUEUE (ulimit -q)")
    path.write_text(scene({unique("ck"): ", packet: vl1b, gli: [socket]"}))
    result = subprocess.run([sys.executable, "-m", "hilgate", "check", str(path)], capture_output=True, text=True,
                            timeout=60, preexec_fn=_low_queue_budget)
    assert "0 new queues" in result.stdout and "RLIMIT_MSGQUEUE" not in result.stdout


# -- what the kernel tells without the mqueue filesystem ----------------------------------------------

def test_budget_without_a_listing_counts_the_scenes_own_queues_and_says_the_rest_is_unknown():
    blind = limits(user_bytes_used=None, queues_existing=None, present=frozenset({"l0_tx_dlnk_phy", "l0_rx_dlnk_phy"}),
                   own_bytes=2 * 1290)
    need = scene_need(links(2), blind)
    assert need.new_queues == 2  # l0's two exist, asked for by name
    text = describe(need, blind)
    assert "819200 bytes (in use: unknown, 2580 by this scene's existing queues)" in text
    assert "queues_max: 256 (how many exist: unknown)" in text and "mqueue filesystem" in text
    # what is known still binds: the scene's own queues count against the budget
    roomy = limits(user_bytes_used=None, queues_existing=None, queues_max=1000, present=blind.present,
                   own_bytes=blind.own_bytes)
    assert budget_problems(scene_need(links(317), roomy), roomy) == []  # 632 new × 1290 + 2580 = 817 860
    problems = budget_problems(scene_need(links(318), roomy), roomy)  # 634 new × 1290 + 2580 = 820 440
    assert len(problems) == 1 and "this user has at least 2580 in use of 819200" in problems[0]
    # and a count above queues_max needs no listing to be certain
    assert budget_problems(scene_need(links(129), blind), blind) == []  # 256 new queues
    problems = budget_problems(scene_need(links(130), blind), blind)  # 258
    assert len(problems) == 1 and "258 new queues and those that exist (how many: unknown)" in problems[0]


def test_check_sees_the_queues_a_running_daemon_holds(daemon_of):
    """The issue's case: `hilgate check` said "(0 in use)" while a daemon held four queues, because it
    looked for them in an unmounted /dev/mqueue.  Asked of the queue API, they are there either way."""
    a, b = unique("hq"), unique("hq")
    text = scene({a: ", packet: vl1b", b: ", packet: vl1b"})
    daemon = daemon_of(text, [a, b])
    assert queue_exists(a) == [True, True] and queue_exists(b) == [True, True]
    result = subprocess.run([sys.executable, "-m", "hilgate", "check", str(daemon.scene)], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "2 of 2 links with POSIX queues: 0 new queues" in result.stdout
    held = sum(probe_queue(name)[1] for link in (a, b) for name in queue_names(link))
    assert held >= 4 * 10 * (1 + 271 + 96)  # at least vl1b's size each (dccomms' 8192 when unlimited)
    if read_limits().listed:
        used = int(result.stdout.split(" bytes (")[1].split(" in use)")[0])
        assert used >= held
    else:
        assert f"(in use: unknown, {held} by this scene's existing queues)" in result.stdout
