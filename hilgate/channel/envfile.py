"""The Acoustics Toolbox's BELLHOP input, written from a :class:`~hilgate.models.environment.Water`.

An environment file (``ROOT.env``, and ``ROOT.bty`` for a sloping bottom) is the interface every
BELLHOP program reads: the Toolbox's own ``bellhop.exe ROOT`` and pelagic's ``bellhop.load``.  Writing
it is our own text (the format is the Toolbox's documented input); nothing of BELLHOP is imported.
Pure: strings out, the runner writes them.
"""

from __future__ import annotations

from ..models.environment import Water

__all__ = ["TL_RUN", "ARRIVALS_RUN", "env_text", "bty_text", "RUN_LETTERS"]

RUN_LETTERS = {"incoherent": "I", "coherent": "C", "semicoherent": "S"}
TL_RUN = "tl"
ARRIVALS_RUN = "arrivals"
ANGLE_DEG = 80.0
"""The beam fan: ±80° from horizontal, so that the steep paths of shallow water near the source are there."""


def _num(x: float) -> str:
    return repr(float(x))


def _list(values: list[float]) -> str:
    """A vector the way BELLHOP reads it: every value, then ``/``."""
    return " ".join(_num(v) for v in values) + " /"


def env_text(water: Water, frequency_hz: float, kind: str, title: str = "hilgate",
             sources: list[float] | None = None, beams: int | None = None, run: str | None = None) -> str:
    """The ``.env`` text of one BELLHOP run: transmission loss on the water's grid (``kind`` =
    :data:`TL_RUN`) or the arrivals on its arrival grid (:data:`ARRIVALS_RUN`, written as ASCII), for
    the water's source depths or ``sources``, with a fan of ``beams`` (default: the water's, 0 when it
    is to be found by convergence) and, for TL, the ``run`` (default: the water's)."""
    deepest = water.deepest_m
    top = "R" if water.surface == "rigid" else "V"
    # C: c-linear interpolation; W: attenuation in dB/wavelength; T: Thorp volume attenuation
    lines = [f"'{title[:70]}'", _num(frequency_hz), "1", f"'C{top}WT'", f"0 0.0 {_num(deepest)}"]
    points = list(water.sound_speed)
    if points[0][0] > 0.0:
        points.insert(0, (0.0, points[0][1]))
    if points[-1][0] < deepest:
        points.append((deepest, points[-1][1]))
    for z, c in points:
        lines.append(f"{_num(z)} {_num(c)} /")
    bottom = water.bottom
    lines.append("'A*' 0.0" if water.bathymetry else "'A' 0.0")
    lines.append(f"{_num(deepest)} {_num(bottom.speed_mps)} 0.0 {_num(bottom.density)} "
                 f"{_num(bottom.attenuation_db_per_wavelength)} /")
    sources = water.source_grid() if sources is None else sources
    if kind == TL_RUN:
        receivers, ranges = water.receiver_grid(), water.range_grid()
    else:
        receivers, ranges = water.receiver_grid(water.arrival_depths), water.range_grid(water.arrival_ranges)
    lines += [str(len(sources)), _list(sources)]
    lines += [str(len(receivers)), _list(receivers)]
    lines += [str(len(ranges)), _list([r / 1000.0 for r in ranges])]
    letter = RUN_LETTERS[run or water.run] if kind == TL_RUN else "A"
    lines.append(f"'{letter}B'")
    if beams is None:
        beams = water.beams if isinstance(water.beams, int) else 0
    lines.append(str(beams))
    lines.append(f"{_num(-ANGLE_DEG)} {_num(ANGLE_DEG)} /")
    lines.append(f"0.0 {_num(deepest * 1.1)} {_num(water.range_m * 1.02 / 1000.0)}")
    return "\n".join(lines) + "\n"


def bty_text(water: Water) -> str:
    """The ``.bty`` bathymetry file: depth against range (km), linear in between, reaching past the
    grid so BELLHOP never runs off its end."""
    points = sorted(water.bathymetry)
    if points[0][0] > 0.0:
        points.insert(0, (0.0, points[0][1]))
    far = water.range_m * 1.05
    if points[-1][0] < far:
        points.append((far, points[-1][1]))
    lines = ["'L'", str(len(points))]
    lines += [f"{_num(r / 1000.0)} {_num(d)}" for r, d in points]
    return "\n".join(lines) + "\n"
