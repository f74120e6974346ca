"""What the benchmarks share about their peers: where the peer scripts are, running one in its own
process with its peak memory, and printing a ratio as min/median/max.

A benchmark prints only what it measured in the same run: a peer that is not installed is "not run",
never a remembered figure."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def _peers_dir() -> str:
    """shared/peers/ beside the repository, or beside a folder above it (a git worktree kept in a
    subfolder of the checkout's parent); beside the repository if there is none."""
    repository = os.path.dirname(HERE)
    folder = os.path.dirname(repository)
    while True:
        candidate = os.path.join(folder, "shared", "peers")
        if os.path.isdir(candidate):
            return candidate
        parent = os.path.dirname(folder)
        if parent == folder:
            return os.path.join(os.path.dirname(repository), "shared", "peers")
        folder = parent


PEERS = _peers_dir()
"""The peers' scripts (../shared/peers/ next to the repository); ``--ns3-script PATH`` elsewhere."""


def run_json(argv: list[str]) -> tuple[dict, float]:
    """Run ``argv``, whose last stdout line is one JSON object; return it and the process's peak
    resident memory in MB (``wait4``'s rusage: this child alone, not the benchmark's other children)."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        process = subprocess.Popen(argv, stdout=out, stderr=err, text=True)
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        lines, errors = out.read().strip().splitlines(), err.read().strip().splitlines()
    if process.returncode != 0 or not lines:
        last = (errors or ["(no output)"])[-1]
        raise RuntimeError(f"{os.path.basename(argv[1])} exited with {process.returncode}: {last}")
    return json.loads(lines[-1]), usage.ru_maxrss / 1024


def spread(values: list[float], digits: int = 2) -> str:
    """``min / median / max`` of a ratio (or of anything measured each repeat)."""
    if not values:
        return "not run"
    return " / ".join(f"{v:.{digits}f}" for v in (min(values), statistics.median(values), max(values)))


def check_python(path: str | None, module: str) -> str | None:
    """Why ``path`` cannot run the peer (None if it can): missing, or it cannot import ``module``."""
    if not path:
        return "no --ns3-python given"
    if not os.access(path, os.X_OK):
        return f"{path} is not an executable"
    probe = subprocess.run([path, "-c", f"import importlib.util, sys; sys.exit(importlib.util.find_spec({module!r}) is None)"],
                           capture_output=True)
    return None if probe.returncode == 0 else f"{path} has no {module!r} module"
