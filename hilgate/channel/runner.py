"""Running BELLHOP as a separate program and keeping what it computed on disk.

BELLHOP implementations are GPL (the Acoustics Toolbox; pelagic, GPL-3.0-or-later), hilgate is MIT: it
never imports one.  It writes the run's environment file (``envfile.py``), starts the program the user
installed as a process, and reads the ``.shd``/``.arr`` files it writes with its own readers.  The
program is, in this order: ``--bellhop``/``HILGATE_BELLHOP`` (a command; the file root is appended), the
Acoustics Toolbox's ``bellhop.exe`` on the PATH, or this checkout's ``.venv-bellhop`` (pelagic, ``make
.venv-bellhop``) running ``tools/bellhop_run.py``.

What a run gives is reduced at once to the grids a lookup needs (TL; the first arrival's delay and its
slopes, ``delays.py``; the delay spread) and cached as ``HASH.fields`` (``fieldcache.py``: checksummed)
under ``$HILGATE_CACHE`` (default ``~/.cache/hilgate/bellhop``), where HASH is the SHA-256 of everything
the fields depend on: the environment and bathymetry files exactly as BELLHOP reads them, the arrival
threshold, how the fan is chosen (``beams.py``) and this reduction's version.  A changed profile, bottom,
grid or frequency is a new hash; an old file is never reused for it.  A damaged file (truncated, a bit
flipped) is one warning, and the fields are computed again and the file replaced.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from ..models.bellhop_fields import TL_CAP, Fields
from ..models.environment import AUTO_BEAMS, Water
from .arrfile import read_arr
from .beams import MOST_BEAMS, SHARE, TOLERANCE_DB, VERSION as BEAMS_RULE, Choice, choose_beams, judged_sources
from .delays import DelayReduction
from .envfile import ARRIVALS_RUN, TL_RUN, bty_text, env_text
from .fieldcache import CacheFileError, decode, encode
from .shdfile import FieldFileError, ShadeFile, read_shd

__all__ = ["BellhopError", "Program", "find_program", "cache_dir", "field_key", "cache_file", "prepare_fields",
           "Progress"]

log = logging.getLogger(__name__)

REDUCTION = 4
"""The version of what the cache holds (bump it when the reduction changes)."""
RUN_TIMEOUT_S = 3600.0
MAX_OUTPUT_BYTES = 2 * 1024 ** 3

Progress = Callable[[int, int, str], None]
"""``progress(done, total, what)``: told before each run and once at the end."""


class BellhopError(Exception):
    """BELLHOP could not be run or its output not read: one line, what to do."""


@dataclass(frozen=True)
class Program:
    """How to start BELLHOP: ``argv`` + the file root."""

    argv: tuple[str, ...]
    name: str

    def __str__(self) -> str:
        return self.name


def _checkout() -> str:
    """The source checkout hilgate runs from (where ``tools/`` and ``.venv-bellhop`` are)."""
    return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def find_program(command: str | None = None) -> Program:
    """The BELLHOP program (the module's doc says in which order it is looked for)."""
    command = command or os.environ.get("HILGATE_BELLHOP") or None
    if command:
        argv = tuple(shlex.split(command))
        if not argv:
            raise BellhopError("the BELLHOP command is empty")
        return Program(argv, command)
    exe = shutil.which("bellhop.exe") or shutil.which("bellhop")
    if exe:
        return Program((exe,), exe)
    root = _checkout()
    python = os.path.join(root, ".venv-bellhop", "bin", "python")
    script = os.path.join(root, "tools", "bellhop_run.py")
    if os.path.exists(python) and os.path.exists(script):
        return Program((python, script), f"pelagic ({python} {script})")
    raise BellhopError("no BELLHOP program: install one (make .venv-bellhop: pelagic in an environment of its own; "
                       "or the Acoustics Toolbox's bellhop.exe on the PATH), or name it with --bellhop / "
                       "HILGATE_BELLHOP (docs/channel-models.md, 'BELLHOP')")


def cache_dir() -> str:
    base = os.environ.get("HILGATE_CACHE")
    if not base:
        base = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "hilgate")
    return os.path.join(base, "bellhop")


def field_key(water: Water, frequency_hz: float) -> str:
    """The hash that names one frequency's fields: what BELLHOP reads, and how it is reduced."""
    h = hashlib.sha256()
    fan = (f"beams by convergence {BEAMS_RULE} {TOLERANCE_DB!r} {SHARE!r} {MOST_BEAMS}" if water.beams == AUTO_BEAMS
           else "beams as given")
    for part in (f"hilgate-fields-{REDUCTION}", env_text(water, frequency_hz, TL_RUN),
                 env_text(water, frequency_hz, ARRIVALS_RUN), bty_text(water) if water.bathymetry else "",
                 repr(water.threshold_db), repr(water.surface_z_m), fan):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def _run(program: Program, workdir: str, name: str, env: str, bty: str | None, suffix: str) -> bytes:
    root = os.path.join(workdir, name)
    with open(root + ".env", "w", encoding="ascii") as fh:
        fh.write(env)
    if bty is not None:
        with open(root + ".bty", "w", encoding="ascii") as fh:
            fh.write(bty)
    try:
        done = subprocess.run(list(program.argv) + [root], cwd=workdir, stdin=subprocess.DEVNULL,
                              capture_output=True, timeout=RUN_TIMEOUT_S, check=False)
    except FileNotFoundError:
        raise BellhopError(f"cannot start BELLHOP ({program}): no such program") from None
    except PermissionError:
        raise BellhopError(f"cannot start BELLHOP ({program}): not executable") from None
    except subprocess.TimeoutExpired:
        raise BellhopError(f"BELLHOP ({program}) ran longer than {RUN_TIMEOUT_S:g} s on {name}") from None
    out = root + suffix
    if done.returncode != 0 or not os.path.exists(out):
        said = (done.stderr or done.stdout).decode("utf-8", "replace").strip().splitlines()
        last = said[-1][:300] if said else f"exit status {done.returncode}"
        raise BellhopError(f"BELLHOP ({program}) failed on {name}: {last}")
    if os.path.getsize(out) > MAX_OUTPUT_BYTES:
        raise BellhopError(f"BELLHOP's {name}{suffix} is larger than {MAX_OUTPUT_BYTES} bytes: a smaller grid")
    with open(out, "rb") as fh:
        return fh.read()


class Steps:
    """The runs of a preparation, for the progress bar: ``steps(what)`` before each run; ``more(n)`` when
    more runs turn out to be needed (a fan that has not converged yet)."""

    def __init__(self, progress: Progress | None):
        self.progress = progress
        self.done = 0
        self.total = 0

    def more(self, n: int) -> None:
        self.total += n

    def __call__(self, what: str) -> None:
        if self.progress is not None:
            self.progress(self.done, max(self.total, self.done + 1), what)
        self.done += 1

    def end(self) -> None:
        if self.progress is not None:
            self.progress(self.done, self.done, "done")


def _shade(program: Program, workdir: str, text: str, bty: str | None) -> ShadeFile:
    try:
        return read_shd(_run(program, workdir, "tl", text, bty, ".shd"))
    except FieldFileError as exc:
        raise BellhopError(f"BELLHOP ({program}) wrote a file hilgate cannot read: {exc}") from None


def _fan(water: Water, frequency_hz: float, program: Program, workdir: str, bty: str | None,
         steps: Steps) -> Choice:
    """The fan found by convergence (``beams.py``), judged on incoherent TL whatever the water's run."""
    judge = dataclasses.replace(water, run="incoherent")
    sources = water.source_grid()
    judged = judged_sources(len(sources))
    khz = f"{frequency_hz / 1000:g} kHz"
    tried = [0]

    def trace(beams: int) -> np.ndarray:
        tried[0] += 1
        if tried[0] > 2:
            steps.more(len(judged))
        planes = []
        for i in judged:
            steps(f"{khz}: transmission loss with {beams} beams from {sources[i]:g} m")
            text = env_text(judge, frequency_hz, TL_RUN, sources=[sources[i]], beams=beams)
            planes.append(_shade(program, workdir, text, bty).transmission_loss_db()[0])
        return np.stack(planes)

    return choose_beams(trace, judge, [sources[i] for i in judged], TL_CAP, BellhopError)


def compute(water: Water, frequency_hz: float, program: Program, workdir: str,
            steps: Steps | None = None) -> dict[str, np.ndarray]:
    """Run BELLHOP at one frequency and reduce its output to the lookup's grids as it comes: the fan
    (found by convergence unless the water gives it), the TL (every source depth in one run for a given
    fan; one run per source depth for a converged one, whose many beams would exceed a program's limits
    in one), then the arrivals one source depth at a time (an arrivals file holds every path, tens of
    megabytes per source depth in shallow water)."""
    steps = steps or Steps(None)
    bty = bty_text(water) if water.bathymetry else None
    khz = f"{frequency_hz / 1000:g} kHz"
    sources = water.source_grid()
    auto = water.beams == AUTO_BEAMS
    judged = judged_sources(len(sources)) if auto else []
    reused = judged if auto and water.run == "incoherent" else []
    steps.more((2 * len(judged) + len(sources) - len(reused)) if auto else 1)
    steps.more(len(sources))
    choice = _fan(water, frequency_hz, program, workdir, bty, steps) if auto else None
    beams = choice.beams if choice is not None else int(water.beams)
    if choice is None:
        steps(f"{khz}: transmission loss")
        shade = _shade(program, workdir, env_text(water, frequency_hz, TL_RUN), bty)
        tl, depths, ranges = shade.transmission_loss_db(), shade.receiver_depths, shade.ranges
        source_depths = shade.source_depths
    else:
        planes, source_depths = [], []
        for i, zs in enumerate(sources):
            if i in reused:
                planes.append(choice.tl[reused.index(i)])
            else:
                steps(f"{khz}: transmission loss with {beams} beams from {zs:g} m")
                shade = _shade(program, workdir, env_text(water, frequency_hz, TL_RUN, sources=[zs], beams=beams),
                               bty)
                planes.append(shade.transmission_loss_db()[0])
            source_depths.append(zs)
        tl, source_depths = np.stack(planes), np.asarray(source_depths)
        depths, ranges = np.asarray(water.receiver_grid()), np.asarray(water.range_grid())
    try:
        delays = DelayReduction(sources, water.threshold_db, water.mean_speed_mps)
        for n, zs in enumerate(sources):
            steps(f"{khz}: arrivals from {zs:g} m ({n + 1}/{len(sources)})")
            text = _run(program, workdir, "arr", env_text(water, frequency_hz, ARRIVALS_RUN, sources=[zs],
                                                          beams=beams), bty, ".arr").decode("latin-1")
            arrivals = read_arr(text)
            del text
            delays.add(arrivals)
    except FieldFileError as exc:
        raise BellhopError(f"BELLHOP ({program}) wrote a file hilgate cannot read: {exc}") from None
    tl[~np.isfinite(tl) | (tl > TL_CAP)] = TL_CAP
    change = np.nan if choice is None or choice.change_db is None else choice.change_db
    largest = np.nan if choice is None or choice.largest_db is None else choice.largest_db
    return {"frequency_hz": np.array(frequency_hz), "sources": source_depths, "depths": depths,
            "ranges": ranges, "tl": tl, "arrival_depths": delays.depths, "arrival_ranges": delays.ranges,
            "beams": np.array(beams), "beams_change_db": np.array(change), "beams_largest_db": np.array(largest),
            **delays.result()}


def to_fields(arrays: dict[str, np.ndarray], water: Water) -> Fields:
    return Fields(float(arrays["frequency_hz"]), arrays["sources"], arrays["depths"], arrays["ranges"],
                  arrays["tl"], arrays["first"], arrays["spread"], water.mean_speed_mps,
                  arrays["arrival_depths"], arrays["arrival_ranges"],
                  (arrays["first_dz"], arrays["first_dr"], arrays["first_ds"]),
                  fan=(int(arrays["beams"]), float(arrays["beams_change_db"]), float(arrays["beams_largest_db"])))


def cache_file(cache: str, water: Water, frequency_hz: float) -> str:
    """Where the fields of ``water`` at ``frequency_hz`` are cached in the directory ``cache``."""
    return os.path.join(cache, field_key(water, frequency_hz) + ".fields")


def _load(path: str) -> dict[str, np.ndarray] | None:
    """The cached arrays, or None (and one warning) when the file cannot be believed."""
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_OUTPUT_BYTES + 1)
        if len(data) > MAX_OUTPUT_BYTES:
            raise CacheFileError(f"larger than {MAX_OUTPUT_BYTES} bytes")
        return decode(data)
    except (OSError, CacheFileError) as exc:
        log.warning("cached BELLHOP fields %s unreadable (%s): computing them again", path, exc)
        return None


def _store(path: str, arrays: dict[str, np.ndarray]) -> None:
    """Write the cache file whole or not at all (a reader never sees half of it)."""
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), suffix=".fields.tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(encode(arrays))
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def prepare_fields(water: Water, frequencies: Iterable[float], *, program: Program | None = None,
                   cache: str | None = None, progress: Progress | None = None) -> list[Fields]:
    """The fields of ``water`` at each frequency (Hz): from the cache, or computed by BELLHOP and cached."""
    cache = cache_dir() if cache is None else cache
    wanted = sorted({float(f) for f in frequencies})
    found: dict[float, Fields] = {}
    missing = []
    for hz in wanted:
        path = cache_file(cache, water, hz)
        arrays = _load(path) if os.path.exists(path) else None
        fields = None
        if arrays is not None:
            try:
                fields = to_fields(arrays, water)
            except (KeyError, ValueError, TypeError, IndexError) as exc:  # another version's, or tampered with
                log.warning("cached BELLHOP fields %s do not fit (%s): computing them again", path, exc)
        if fields is None:
            missing.append(hz)
        else:
            found[hz] = fields
    if missing:
        program = program or find_program()
        os.makedirs(cache, mode=0o700, exist_ok=True)
        steps = Steps(progress)
        for hz in missing:
            with tempfile.TemporaryDirectory(prefix="hilgate-bellhop-") as workdir:
                arrays = compute(water, hz, program, workdir, steps)
            path = cache_file(cache, water, hz)
            _store(path, arrays)
            log.info("BELLHOP fields at %g Hz (%d beams) cached in %s", hz, int(arrays["beams"]), path)
            found[hz] = to_fields(arrays, water)
        steps.end()
    return [found[hz] for hz in wanted]


def bar(stream=None) -> Progress:
    """A progress bar on stderr (a terminal) or one line per run (a log file)."""
    stream = stream or sys.stderr

    def show(done: int, total: int, what: str) -> None:
        width = 30
        filled = width * done // max(total, 1)
        line = f"BELLHOP [{'#' * filled}{'.' * (width - filled)}] {done}/{total} {what}"
        if stream.isatty():
            stream.write("\r" + line.ljust(100) + ("\n" if done == total else ""))
        else:
            stream.write(line + "\n")
        stream.flush()

    return show
