"""``hilgate run --realtime``: the loop thread at real-time priority where the host allows it, else at the
lowest niceness allowed, and the daemon says which (log, ``hilgate status``, ``status --json``).

What the host allows is decided by the kernel, not mocked: the privileged cases run where this process
may take SCHED_RR (root here) and skip with the reason elsewhere; the unprivileged one takes the
privilege away from the daemon's process before it starts (CAP_SYS_NICE and CAP_IPC_LOCK out of its
capability bounding set, RLIMIT_RTPRIO 0), as a host that does not grant it would; the last one puts
the process in a cgroup with no real-time budget, which refuses SCHED_RR even to root."""

from __future__ import annotations

import ctypes
import json
import os
import resource
import subprocess
import sys
import uuid

import pytest

from daemon_kit import hilgate, quick_scene, unique

PR_CAPBSET_DROP, CAP_SETPCAP, CAP_IPC_LOCK, CAP_SYS_NICE = 24, 8, 14, 23
CPU_CGROUPS = "/sys/fs/cgroup/cpu"

# In a process of its own: the loop's thread raises its priority, then makes a thread and a process,
# and says what each of the three runs at.
THREE = """
import json, subprocess, sys, threading
from hilgate.core.priority import current, raise_priority
got = raise_priority(10)
seen = {}
thread = threading.Thread(target=lambda: seen.update(thread=current().as_dict()))
thread.start(); thread.join()
child = subprocess.run([sys.executable, "-c", "import json; from hilgate.core.priority import current; "
                        "print(json.dumps(current().as_dict()))"], capture_output=True, text=True, check=True)
print(json.dumps({"loop": got.as_dict(), "thread": seen["thread"], "child": json.loads(child.stdout)}))
"""


def _capable(capability: int) -> bool:
    with open("/proc/self/status") as status:
        mask = next(int(line.split()[1], 16) for line in status if line.startswith("CapEff:"))
    return bool(mask >> capability & 1)


def _why_no_real_time() -> str | None:
    """Why this host would refuse the daemon SCHED_RR 10 (None: it allows it), asked of the kernel."""
    probe = subprocess.run([sys.executable, "-c", "import os; os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(10))"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        return f"this host refuses SCHED_RR 10 to the tests' user: {probe.stderr.strip().splitlines()[-1]}"
    return None


def _without_real_time_privileges() -> None:
    """In the daemon's process before it starts: what an unprivileged user has (no CAP_SYS_NICE, no
    CAP_IPC_LOCK after exec, RLIMIT_RTPRIO 0)."""
    resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
    if _capable(CAP_SETPCAP):
        libc = ctypes.CDLL(None, use_errno=True)
        for capability in (CAP_SYS_NICE, CAP_IPC_LOCK):
            if libc.prctl(PR_CAPBSET_DROP, capability, 0, 0, 0) != 0:
                raise OSError(ctypes.get_errno(), "PR_CAPBSET_DROP")


def _lowest_nice_of_this_user() -> int:
    """What RLIMIT_NICE lets a process without CAP_SYS_NICE take (the daemon inherits the limit)."""
    limit = resource.getrlimit(resource.RLIMIT_NICE)[0]
    return -20 if limit == resource.RLIM_INFINITY else max(-20, min(0, 20 - limit))


@pytest.fixture
def no_real_time_budget():
    """A cgroup (v1 ``cpu`` controller) whose real-time budget is 0, and a ``preexec`` that puts the
    daemon's process in it; removed after the test."""
    budget = os.path.join(CPU_CGROUPS, "cpu.rt_runtime_us")
    if not os.path.exists(budget):
        pytest.skip(f"no {budget}: this kernel does not schedule real-time threads by cgroup")
    group = os.path.join(CPU_CGROUPS, f"hilgate-test-{uuid.uuid4().hex[:8]}")
    try:
        os.mkdir(group)
    except OSError as exc:
        pytest.skip(f"cannot make a cgroup here ({exc})")
    try:
        with open(os.path.join(group, "cpu.rt_runtime_us")) as handle:
            assert int(handle.read()) == 0  # (a new group starts with none)

        def enter() -> None:
            with open(os.path.join(group, "cgroup.procs"), "w") as procs:
                procs.write(str(os.getpid()))

        yield enter
    finally:
        with open(os.path.join(group, "cgroup.procs")) as procs:
            assert procs.read().strip() == ""  # every process of the test is gone
        os.rmdir(group)


def test_the_options_are_accepted_and_a_priority_out_of_range_is_refused(tmp_path):
    from hilgate.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["run", "--realtime"]).realtime is True
    args = parser.parse_args(["run", "--realtime-priority", "5"])  # the older option: --realtime at priority 5
    assert (args.realtime, args.realtime_priority) == (False, 5)
    assert parser.parse_args(["run"]).realtime_priority is None
    scene = tmp_path / "scene.yaml"
    scene.write_text(quick_scene("prio", unique("a"), unique("b")))
    refused = hilgate("run", str(scene), "--runtime-dir", str(tmp_path / "rt"), "--realtime-priority", "100")
    assert refused.returncode == 2 and "from 1 to 99" in refused.stderr


def test_without_the_option_the_daemon_says_it_runs_at_normal_priority(daemon_of):
    a, b = unique("a"), unique("b")
    daemon = daemon_of(quick_scene("prio", a, b), [a, b])
    scheduling = daemon.status()["scheduling"]
    assert (scheduling["kind"], scheduling["policy"], scheduling["asked_priority"]) == ("normal", "SCHED_OTHER", 0)
    assert "--realtime not given" in scheduling["text"]


def test_the_loop_takes_real_time_and_what_it_makes_does_not():
    why = _why_no_real_time()
    if why:
        pytest.skip(why)
    seen = json.loads(subprocess.run([sys.executable, "-c", THREE], capture_output=True, text=True, check=True,
                                     timeout=60).stdout)
    assert (seen["loop"]["kind"], seen["loop"]["policy"], seen["loop"]["priority"]) == ("realtime", "SCHED_RR", 10)
    for other in ("thread", "child"):  # Zenoh's threads, a reader's, the scene worker: at normal priority
        assert (seen[other]["policy"], seen[other]["priority"], seen[other]["nice"]) == ("SCHED_OTHER", 0, 0), other


def test_a_daemon_with_realtime_runs_its_loop_at_sched_rr_and_says_so(daemon_of):
    why = _why_no_real_time()
    if why:
        pytest.skip(why)
    a, b = unique("a"), unique("b")
    daemon = daemon_of(quick_scene("prio", a, b), [a, b], "--realtime")
    scheduling = daemon.status()["scheduling"]
    assert (scheduling["kind"], scheduling["policy"], scheduling["priority"]) == ("realtime", "SCHED_RR", 10)
    assert "scheduling: real-time SCHED_RR priority 10" in daemon.output()
    with open(f"/proc/{daemon.process.pid}/sched") as sched:  # the kernel's own word, for the loop's thread
        policy = next(int(line.split(":")[1]) for line in sched if line.startswith("policy"))
    assert policy == os.SCHED_RR
    shown = hilgate("status", "--runtime-dir", daemon.runtime)
    assert "scheduling: real-time SCHED_RR priority 10" in shown.stdout
    as_json = json.loads(hilgate("status", "--json", "--runtime-dir", daemon.runtime).stdout)
    assert as_json["scheduling"]["policy"] == "SCHED_RR"
    if _capable(CAP_IPC_LOCK) or resource.getrlimit(resource.RLIMIT_MEMLOCK)[0] == resource.RLIM_INFINITY:
        assert scheduling["memory_locked"] is True


def test_the_older_option_is_realtime_at_its_priority(daemon_of):
    why = _why_no_real_time()
    if why:
        pytest.skip(why)
    a, b = unique("a"), unique("b")
    daemon = daemon_of(quick_scene("prio", a, b), [a, b], "--realtime-priority", "7")
    scheduling = daemon.status()["scheduling"]
    assert (scheduling["policy"], scheduling["priority"], scheduling["asked_priority"]) == ("SCHED_RR", 7, 7)


def test_a_daemon_without_the_privilege_falls_back_to_niceness_and_says_so(daemon_of):
    if os.geteuid() != 0 and _capable(CAP_SYS_NICE):
        pytest.skip("this user holds CAP_SYS_NICE and cannot give it up (not root)")
    a, b = unique("a"), unique("b")
    daemon = daemon_of(quick_scene("prio", a, b), [a, b], "--realtime", preexec=_without_real_time_privileges)
    scheduling = daemon.status()["scheduling"]
    assert scheduling["policy"] == "SCHED_OTHER" and scheduling["priority"] == 0
    assert scheduling["kind"] == ("nice" if _lowest_nice_of_this_user() < 0 else "normal")
    assert scheduling["nice"] == _lowest_nice_of_this_user()
    assert any("SCHED_RR refused: RLIMIT_RTPRIO is 0" in note for note in scheduling["notes"]), scheduling
    assert scheduling["memory_locked"] is False
    warning = next(line for line in daemon.output().splitlines() if "scheduling:" in line)
    assert "WARNING" in warning and "SCHED_RR refused" in warning and f"nice {scheduling['nice']}" in warning
    shown = hilgate("status", "--runtime-dir", daemon.runtime)
    assert "scheduling: " in shown.stdout and "SCHED_RR refused" in shown.stdout


def test_refused_real_time_even_to_root_the_loop_takes_the_lowest_nice_and_its_threads_do_not(
        daemon_of, no_real_time_budget):
    if not _capable(CAP_SYS_NICE):
        pytest.skip("needs CAP_SYS_NICE: the point is a refusal that does not come from a missing privilege")
    seen = json.loads(subprocess.run([sys.executable, "-c", THREE], capture_output=True, text=True, check=True,
                                     timeout=60, preexec_fn=no_real_time_budget).stdout)
    assert (seen["loop"]["kind"], seen["loop"]["policy"], seen["loop"]["nice"]) == ("nice", "SCHED_OTHER", -20)
    assert "cgroup has no real-time budget" in " ".join(seen["loop"]["notes"])
    for other in ("thread", "child"):
        assert (seen[other]["policy"], seen[other]["nice"]) == ("SCHED_OTHER", 0), other
    a, b = unique("a"), unique("b")
    daemon = daemon_of(quick_scene("prio", a, b), [a, b], "--realtime", preexec=no_real_time_budget)
    scheduling = daemon.status()["scheduling"]
    assert (scheduling["kind"], scheduling["nice"]) == ("nice", -20)
    daemon.close()  # (before the fixture removes the cgroup, which must be empty by then)


def test_the_systemd_unit_lets_the_daemon_take_real_time_for_its_loop_alone():
    """The unit grants the limits (no capability: its bounding set is empty) and the daemon asks; a
    CPUSchedulingPolicy= would put every thread of the daemon, and all it starts, at real-time priority."""
    here = os.path.dirname(os.path.abspath(__file__))
    unit = open(os.path.join(here, "..", "systemd", "hilgate.service")).read()
    lines = {line.split("=", 1)[0]: line.split("=", 1)[1] for line in unit.splitlines()
             if "=" in line and not line.startswith("#")}
    assert "CPUSchedulingPolicy" not in lines and "RestrictRealtime" not in lines
    assert int(lines["LimitRTPRIO"]) >= 10 and lines["LimitMEMLOCK"] == "infinity" and int(lines["LimitNICE"]) < 0
    env = open(os.path.join(here, "..", "systemd", "hilgate.env")).read()
    arguments = next(line for line in env.splitlines() if line.startswith("HILGATE_ARGS="))
    assert "--realtime" in arguments.split("=", 1)[1].split()
