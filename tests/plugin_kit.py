"""Installed packages that add rows to hilgate's tables, made without pip: a folder on ``PYTHONPATH`` holding
the package's modules and its ``NAME-VERSION.dist-info`` (METADATA and entry_points.txt), which is all
``importlib.metadata`` reads.  ``test_plugin_package.py`` installs a real package with pip into a fresh
venv; this kit is for the many cases (clashes, broken packages, every group) that would each need one."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
LABMODEM = REPO / "examples" / "labmodem"


def installed(site: Path, name: str, version: str, entry_points: dict[str, dict[str, str]],
              modules: dict[str, str] | None = None, packages: tuple[Path, ...] = ()) -> Path:
    """``site`` with the package ``name`` ``version`` in it: its entry points by group, its ``modules``
    (relative path → text) and copies of ``packages`` (folders)."""
    info = site / f"{name.replace('-', '_')}-{version}.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    (info / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{key} = {value}\n" for key, value in entries.items())
        for group, entries in entry_points.items()))
    for path, text in (modules or {}).items():
        (site / path).parent.mkdir(parents=True, exist_ok=True)
        (site / path).write_text(text)
    for package in packages:
        shutil.copytree(package, site / package.name, dirs_exist_ok=True)
    return site


def hilgate(site: Path, *argv: str, cwd: Path) -> subprocess.CompletedProcess:
    """``hilgate ARGV`` with ``site`` on the path (answers as they are: the test judges the exit status)."""
    env = dict(os.environ, PYTHONPATH=str(site))
    return subprocess.run([sys.executable, "-m", "hilgate", *argv], cwd=cwd, env=env, capture_output=True,
                          text=True, stdin=subprocess.DEVNULL, timeout=300)
