"""BELLHOP for the tests: the real program (pelagic in ``.venv-bellhop``, as ``make test`` installs it),
made here when a test run started without make finds it missing, once for all workers (a file lock)."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys

from hilgate.channel.runner import Program

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VENV = os.path.join(ROOT, ".venv-bellhop")
PYTHON = os.path.join(VENV, "bin", "python")
SCRIPT = os.path.join(ROOT, "tools", "bellhop_run.py")
PELAGIC = "0.5.0"  # the Makefile's PELAGIC


def ensure_program() -> Program:
    """The BELLHOP program the tests run (made as the Makefile's ``.venv-bellhop`` step makes it)."""
    with open(os.path.join(ROOT, ".venv-bellhop.lock"), "w", encoding="utf-8") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not os.path.exists(os.path.join(VENV, ".installed")):
            subprocess.run([sys.executable, "-m", "venv", VENV], check=True)
            subprocess.run([PYTHON, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                            f"pelagic=={PELAGIC}"], check=True)
            open(os.path.join(VENV, ".installed"), "w", encoding="utf-8").close()
    return Program((PYTHON, SCRIPT), f"pelagic ({PYTHON} {SCRIPT})")


def run_with_report(root: str) -> str:
    """Run BELLHOP on ``root``.env as hilgate does, and also have pelagic report its own values."""
    report = root + ".json"
    subprocess.run([PYTHON, SCRIPT, root, "--report", report], check=True, capture_output=True, timeout=600)
    return report
