"""Installed as users install Python tools (issue 40 item 4): ``python -m build`` makes a wheel and an sdist
with one version, and the wheel, installed into a fresh venv (its dependencies from pip's cache or PyPI,
nothing of the checkout on the path), runs ``hilgate sim`` on a shipped scene, ``hilgate check`` on every
modem preset it carries and ``hilgate view --help``."""

from __future__ import annotations

import email
import os
import subprocess
import tarfile
import zipfile
from pathlib import Path

import pytest

import hilgate
from wheel_kit import build_dist, clean_env, fresh_venv, run


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    result = build_dist(out)
    # setuptools' own warnings (a data folder absent from `packages` gave one per file, about 40 lines)
    output = result.stdout + result.stderr
    assert "absent from the `packages`" not in output and "SetuptoolsDeprecationWarning" not in output, output
    return out


@pytest.fixture(scope="module")
def venv(dist, tmp_path_factory) -> Path:
    return fresh_venv(tmp_path_factory.mktemp("venv"), dist)


def test_build_makes_a_wheel_and_an_sdist_of_one_version(dist):
    version = hilgate.__version__
    wheel = dist / f"hilgate-{version}-py3-none-any.whl"
    sdist = dist / f"hilgate-{version}.tar.gz"
    assert wheel.is_file() and sdist.is_file(), sorted(p.name for p in dist.iterdir())
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
        metadata = email.message_from_bytes(archive.read(f"hilgate-{version}.dist-info/METADATA"))
    assert {"hilgate/web/static/view.js", "hilgate/scenes/demo.yaml", "hilgate/scenes/tank.yaml",
            "hilgate/models/m64.yaml", "hilgate/drivers/s100.py", "hilgate/models/medium.py"} <= names
    assert metadata["Version"] == version and metadata["Requires-Python"] == ">=3.11"
    assert "Programming Language :: Python :: 3.11" in metadata.get_all("Classifier")
    assert {"web", "report"} <= set(metadata.get_all("Provides-Extra"))
    with tarfile.open(sdist) as archive:
        members = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
    assert {"pyproject.toml", "README.md", "hilgate/__init__.py", "scenes/tank.yaml", "models/s100.yaml"} <= members


def test_the_wheel_in_a_fresh_venv_simulates_checks_every_preset_and_has_the_view(venv, tmp_path):
    env = clean_env(venv)
    hilgate_ = venv / "bin" / "hilgate"
    where = run([venv / "bin" / "python", "-c", "import hilgate; print(hilgate.__file__)"], cwd=tmp_path, env=env)
    assert where.stdout.startswith(str(venv)), f"hilgate came from {where.stdout} (the checkout?)"
    assert run([hilgate_, "--version"], cwd=tmp_path, env=env).stdout.strip() == f"hilgate {hilgate.__version__}"
    scenes = Path(where.stdout.strip()).parent / "scenes"
    sim = run([hilgate_, "sim", scenes / "demo.yaml", "--until", "20"], cwd=tmp_path, env=env)
    assert "scene 'demo'" in sim.stdout
    presets = sorted(p.stem for p in (Path(where.stdout.strip()).parent / "models").glob("*.yaml"))
    assert {"s100", "m64", "micromodem"} <= set(presets)
    for preset in presets:
        scene = tmp_path / f"{preset}.yaml"
        scene.write_text(f"channels: {{ch: {{speed_mps: 1500}}}}\n"
                         f"vehicles: {{a: {{pose: {{static: [0, 0, 1]}}}}, b: {{pose: {{static: [10, 0, 1]}}}}}}\n"
                         f"links:\n  x: {{vehicle: a, model: {preset}, address: 1}}\n"
                         f"  y: {{vehicle: b, model: {preset}, address: 2}}\n")
        check = run([hilgate_, "check", scene], cwd=tmp_path, env=env)
        assert check.stdout.rstrip().endswith("ok"), (preset, check.stdout)
    assert "usage: hilgate view" in run([hilgate_, "view", "--help"], cwd=tmp_path, env=env).stdout


def test_without_its_extras_the_wheel_says_what_to_install_and_systemd_does_not_restart_it(venv, tmp_path):
    """The wheel alone has neither tornado nor matplotlib (the extras web and report): ``run --web`` ends
    with exit status 2 (the unit's RestartPreventExitStatus: a restart every 2 s cannot install it) and the
    pip line; ``report`` names its extra too."""
    env = clean_env(venv)
    scene = tmp_path / "one.yaml"
    scene.write_text("channels: {ch: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0, 0, 1]}}}\n"
                     f"links: {{w{os.getpid()}: {{vehicle: a, address: 1, gli: [socket]}}}}\n")
    web = subprocess.run([venv / "bin" / "hilgate", "run", scene, "--web", "0", "--runtime-dir", tmp_path / "rt"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert web.returncode == 2 and "pip install 'hilgate[web]'" in web.stderr, web.stderr
    run([venv / "bin" / "hilgate", "sim", scene, "--until", "5", "--trace", "t.jsonl", "--summary", "s.json", "-q"],
        cwd=tmp_path, env=env)
    report = subprocess.run([venv / "bin" / "hilgate", "report", "t.jsonl", "s.json", "--out", "r"], cwd=tmp_path,
                            env=env, capture_output=True, text=True, timeout=120)
    assert report.returncode != 0 and "pip install 'hilgate[report]'" in report.stderr, report.stderr
