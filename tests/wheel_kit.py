"""hilgate as users install it: a wheel built as a release builds it (``python -m build``), installed into a
fresh venv with nothing of the checkout on its path.  ``test_wheel.py`` checks the wheel itself;
``test_plugin_package.py`` installs a lab's own package beside it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def run(argv, cwd, env=None, timeout=900) -> subprocess.CompletedProcess:
    result = subprocess.run([str(a) for a in argv], cwd=cwd, env=env, capture_output=True, text=True,
                            stdin=subprocess.DEVNULL, timeout=timeout)
    assert result.returncode == 0, f"{' '.join(map(str, argv))}:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result


def build_dist(out: Path) -> subprocess.CompletedProcess:
    """The wheel and the sdist in ``out`` (an isolated build, as a release makes it: pyproject's build
    requirements from pip's cache or PyPI)."""
    return run([sys.executable, "-m", "build", "--outdir", out, REPO], cwd=out)


def fresh_venv(where: Path, dist: Path, *more: str | Path) -> Path:
    """A new venv at ``where`` with the wheel of ``dist`` installed (and ``more``: other requirements)."""
    run([sys.executable, "-m", "venv", where], cwd=where)
    wheel = next(dist.glob("hilgate-*.whl"))
    run([where / "bin" / "python", "-m", "pip", "install", "--quiet", "--disable-pip-version-check", wheel, *more],
        cwd=where)
    return where


def clean_env(venv: Path) -> dict:
    """No PYTHONPATH, no checkout: what a user's shell has after pipx or pip installed the wheel."""
    return {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "HOME": os.environ.get("HOME", "/"), "LANG": "C.UTF-8"}
