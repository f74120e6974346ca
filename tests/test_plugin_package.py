"""A lab's modem as its own package (issue 39 item 1): ``examples/labmodem`` (a driver row, its driver and its
emulated modem, a ``hilgate.drivers`` entry point) installed with pip into a fresh venv beside hilgate's
wheel; its row is used by a scene there, and passes the driver table's behavioural suite
(``test_driver_suite.py``, the same tests every built-in row passes) run by that venv's interpreter.

Slow as ``test_wheel.py`` is (a wheel built, a venv made), and made the same way (``wheel_kit``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from plugin_kit import LABMODEM
from wheel_kit import REPO, build_dist, clean_env, fresh_venv, run


@pytest.fixture(scope="module")
def venv(tmp_path_factory) -> Path:
    dist = tmp_path_factory.mktemp("dist")
    build_dist(dist)
    # pytest: the suite runs in this venv; the package from its folder, as a lab installs its own
    return fresh_venv(tmp_path_factory.mktemp("venv"), dist, "pytest", LABMODEM)


def test_the_installed_row_is_in_the_table_and_a_scene_uses_it(venv, tmp_path):
    env = clean_env(venv)
    where = run([venv / "bin" / "python", "-c", "import labmodem, hilgate; print(labmodem.__file__, hilgate.__file__)"],
                cwd=tmp_path, env=env)
    assert all(path.startswith(str(venv)) for path in where.stdout.split()), where.stdout
    (tmp_path / "lab.yaml").write_text(
        "channels: {ac: {speed_mps: 1500}}\n"
        "vehicles: {a: {pose: {static: [0, 0, 1]}}, b: {pose: {static: [10, 0, 1]}}}\n"
        f"links:\n  x: {{vehicle: a, address: 1, backend: labmodem, port: {tmp_path / 'pty'}}}\n"
        f"  y: {{vehicle: b, address: 2, emulate: {{protocol: labmodem, pty: {tmp_path / 'pty'}}}}}\n")
    check = run([venv / "bin" / "hilgate", "check", "lab.yaml"], cwd=tmp_path, env=env)
    assert check.stdout.rstrip().endswith("ok") and "x: labmodem on a" in check.stdout, check.stdout


def test_the_installed_row_passes_the_driver_table_suite(venv, tmp_path):
    env = {**clean_env(venv), "HILGATE_SUITE_ROWS": "labmodem"}
    suite = run([venv / "bin" / "python", "-m", "pytest", "-q", "-p", "no:cacheprovider",
                 REPO / "tests" / "test_driver_suite.py"], cwd=tmp_path, env=env, timeout=1800)
    # every test of the suite, for the row's one way (a pty): both start orders, the replug, the swap
    assert suite.stdout.rstrip().splitlines()[-1].startswith("4 passed"), suite.stdout
