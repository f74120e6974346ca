"""Our reader of the Acoustics Toolbox's ASCII arrivals file (``.arr``, run type ``'A'``): every path's
amplitude and delay at every receiver.

Sans-I/O: text in, arrays out.  The layout (the Toolbox's documented 2-D ASCII output, whitespace
separated)::

    '2D'
    frequency (Hz)
    Nsz  source depths…
    Nrz  receiver depths…
    Nrr  receiver ranges (m)…
    for each source depth:
        the largest number of arrivals at any receiver
        for each receiver depth, for each range:
            Narr
            Narr lines: amplitude, phase (°), delay (s, real and imaginary), source angle,
                        receiver angle (°), surface bounces, bottom bounces

The arrivals come out flat (one row per path) with the offset of each receiver's first row, the way
numpy reduces them (:func:`first_and_spread`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .shdfile import FieldFileError

__all__ = ["ArrivalFile", "read_arr", "first_and_spread"]

MAX_ARRIVALS = 50_000_000


@dataclass(frozen=True)
class ArrivalFile:
    frequency_hz: float
    source_depths: np.ndarray    # (Nsz,)
    receiver_depths: np.ndarray  # (Nrz,)
    ranges: np.ndarray           # (Nrr,) metres
    offsets: np.ndarray          # (Nsz·Nrz·Nrr + 1,): receiver k's arrivals are rows offsets[k]:offsets[k+1]
    amplitude: np.ndarray        # (N,)
    phase_deg: np.ndarray        # (N,)
    delay_s: np.ndarray          # (N,) the real part of the delay
    source_angle_deg: np.ndarray
    receiver_angle_deg: np.ndarray
    surface_bounces: np.ndarray  # (N,) int
    bottom_bounces: np.ndarray   # (N,) int

    @property
    def shape(self) -> tuple[int, int, int]:
        return (len(self.source_depths), len(self.receiver_depths), len(self.ranges))

    def at(self, isz: int, irz: int, irr: int) -> slice:
        """The rows of the arrivals at one receiver for one source depth."""
        nsz, nrz, nrr = self.shape
        k = (isz * nrz + irz) * nrr + irr
        return slice(int(self.offsets[k]), int(self.offsets[k + 1]))


def read_arr(text: str) -> ArrivalFile:
    """Every arrival of a 2-D ASCII arrivals file.  After its kind, the file is numbers only: numpy
    parses them in one pass (a file of tens of megabytes takes a fraction of a second), and the counts
    are walked to find each receiver's rows."""
    head, _, rest = text.lstrip().partition("\n") if text.strip() else ("", "", "")
    kind = head.strip().strip("'\"")
    if not head.strip():
        raise FieldFileError("truncated arrivals file: it ends before its kind")
    if kind != "2D":
        raise FieldFileError(f"not a 2-D ASCII arrivals file: it starts with {kind[:20]!r}, not '2D'")
    try:
        values = np.fromstring(rest, sep=" ") if rest.strip() else np.zeros(0)
    except ValueError:
        raise FieldFileError("not an arrivals file: it holds something that is not a number") from None
    if not np.all(np.isfinite(values)):
        raise FieldFileError("not an arrivals file: it holds values that are not finite")
    size = len(values)
    i = 0

    def count(what: str, limit: int) -> int:
        nonlocal i
        if i >= size:
            raise FieldFileError(f"truncated arrivals file: it ends before {what}")
        value = values[i]
        if value != int(value) or not 0 <= value <= limit:
            raise FieldFileError(f"not an arrivals file: {what} {value:g}")
        i += 1
        return int(value)

    if size < 1:
        raise FieldFileError("truncated arrivals file: it ends before the frequency")
    frequency = float(values[0])
    i = 1
    axes = []
    for what in ("source depths", "receiver depths", "ranges"):
        n = count(f"the number of {what}", 10_000_000)
        if n < 1:
            raise FieldFileError(f"not an arrivals file: no {what}")
        if i + n > size:
            raise FieldFileError(f"truncated arrivals file: it ends within the {what}")
        axes.append(values[i:i + n].copy())
        i += n
    nsz, nrz, nrr = (len(a) for a in axes)
    if nsz * nrz * nrr > MAX_ARRIVALS:
        raise FieldFileError(f"not an arrivals file: {nsz}×{nrz}×{nrr} receivers")
    counts = np.zeros(nsz * nrz * nrr, dtype=np.int64)
    starts = np.zeros(nsz * nrz * nrr, dtype=np.int64)
    k = 0
    for _ in range(nsz):
        most = count("the largest number of arrivals", MAX_ARRIVALS)
        for _ in range(nrz * nrr):
            n = count("a number of arrivals", most)
            starts[k] = i
            counts[k] = n
            i += 8 * n
            if i > size:
                raise FieldFileError("truncated arrivals file: it ends within an arrival")
            k += 1
    total = int(counts.sum())
    if total > MAX_ARRIVALS:
        raise FieldFileError(f"not an arrivals file: more than {MAX_ARRIVALS} arrivals")
    offsets = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    # row r of receiver k starts at starts[k] + 8·(r − offsets[k])
    row_start = np.repeat(starts - 8 * offsets[:-1], counts) + 8 * np.arange(total)
    table = values[row_start[:, None] + np.arange(8)[None, :]]
    return ArrivalFile(frequency, axes[0], axes[1], axes[2], offsets, table[:, 0], table[:, 1], table[:, 2],
                       table[:, 4], table[:, 5], table[:, 6].astype(np.int64), table[:, 7].astype(np.int64))


def first_and_spread(arrivals: ArrivalFile, threshold_db: float) -> tuple[np.ndarray, np.ndarray]:
    """Per receiver (shape ``(Nsz, Nrz, Nrr)``): the delay of the first arrival within ``threshold_db``
    of the strongest there, and the RMS delay spread of those arrivals (power-weighted); NaN where
    nothing arrives.  Vectorised: one pass over the flat rows."""
    shape = arrivals.shape
    n = int(np.prod(shape))
    counts = np.diff(arrivals.offsets)
    owner = np.repeat(np.arange(n), counts)
    amp = np.abs(arrivals.amplitude)
    delay = arrivals.delay_s
    strongest = np.zeros(n)
    np.maximum.at(strongest, owner, amp)
    keep = amp >= strongest[owner] * 10.0 ** (-threshold_db / 20.0)
    keep &= amp > 0.0
    first = np.full(n, np.inf)
    np.minimum.at(first, owner[keep], delay[keep])
    power = np.where(keep, amp * amp, 0.0)
    total = np.bincount(owner, weights=power, minlength=n)
    mean = np.bincount(owner, weights=power * delay, minlength=n)
    square = np.bincount(owner, weights=power * delay * delay, minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = mean / total
        spread = np.sqrt(np.maximum(square / total - mean * mean, 0.0))
    first[~np.isfinite(first)] = np.nan
    spread[total <= 0.0] = np.nan
    return first.reshape(shape), spread.reshape(shape)
