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


@pytest.fixture
def busy_host(tmp_path):
    """The topside PC as labs have it (tests/loadkit.py): for the test's duration, neighbours at its own
    priority, a CPU-bound one and one that wakes every 6 ms for each of the host's cores (every core is
    contested), and a writer that syncs 256 MiB at a time.  A test that takes it asserts what the modems do
    exactly as without it: host load must change none of it.  (Twice as many, as :func:`crowded_host` has,
    cost the parallel part of make test 25 s of its 476 on a clean clone here: it is CPU-bound on two cores.)"""
    with _neighbours(tmp_path, per_core=1) as neighbours:
        yield neighbours


@pytest.fixture
def crowded_host(tmp_path):
    """Issue 36's reproduction of a lost S100 frame: twice as many CPU-bound neighbours and as many that wake
    every 6 ms as the host has cores, and the writer that syncs."""
    with _neighbours(tmp_path, per_core=2) as neighbours:
        yield neighbours


def _neighbours(tmp_path, per_core: int):
    """``per_core`` CPU hogs and as many wakers for each of the host's cores, and one writer that syncs."""
    from loadkit import Neighbours

    cores = os.cpu_count() or 1
    return Neighbours(hogs=per_core * cores, wakers=per_core * cores, writers=1, mib=256, directory=str(tmp_path))


# Tests that must not share the machine with the rest of the suite: they time a serial line or a
# preemption in real time, or run daemons the kit does not start (so nothing waits for the user's
# POSIX-queue budget, which every test run on the machine shares) with many links.  `make test` runs
# them after the parallel part, alone (-m serial); a plain `pytest` runs everything as before.
SERIAL = {
    "test_field_realtime.py": "a preemption, provoked and measured",
    "test_realtime.py": "the real-time scheduler's own timing",
    "test_readme.py::test_every_quick_start_command_prints_what_the_readme_shows":
        "the README's walk: its daemons are the README's commands, which the kit does not start",
    "test_formation.py::test_the_application_classes_keep_formation_through_hilgate_app":
        "examples/formation/run.py: five links' queues in a daemon of its own",
    "test_benchmarks_run.py::test_a_benchmark_runs_to_its_summary_on_a_small_case":
        "the benchmarks' daemons and anchors make their own queues (gli_roundtrip.py's relay four of 80 kB)",
    "test_benchmarks_run.py::test_a_benchmark_with_daemons_prints_its_figures_on_a_small_case":
        "the benchmarks' own daemons (several, one after the other), their processes pinned to CPUs",
}


# The files that take longest on one worker (a clean clone's `make test`, --durations), handed out first: the
# workers take files in the order they are collected, and a long file taken last keeps one worker busy while the
# others have finished (longest first is the classic cure).  Every other file keeps its place after them.
LONGEST_FIRST = ["test_install.py", "test_plugin_package.py", "test_formation.py", "test_wheel.py",
                 "test_s100_emulator.py", "test_unet.py", "test_trace_fuzz.py", "test_web.py", "test_door_fairness.py",
                 "test_multihost.py", "test_web_access.py", "test_web_operator.py", "test_bellhop.py",
                 "test_water_examples.py", "test_emulator_acks.py", "test_modems_e2e.py", "test_report.py",
                 "test_report_figures.py", "test_live_poses.py", "test_swap_accounting.py"]


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in SERIAL or f"{item.path.name}::{item.originalname}" in SERIAL:
            item.add_marker(pytest.mark.serial)
    rank = {name: n for n, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # (stable: the rest as collected)
