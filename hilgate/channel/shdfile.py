"""Our reader of the Acoustics Toolbox's shade file (``.shd``): the complex pressure on a grid.

Sans-I/O: bytes in, arrays out.  The layout (the Toolbox's documented binary output, little-endian,
fixed-length records whose length in 4-byte words is the file's first integer):

====== ===========================================================================================
record what it holds
====== ===========================================================================================
0      record length (int32), title (80 characters)
1      plot type (10 characters: ``rectilin``, ``irregular``…)
2      Nfreq, Ntheta, Nsx, Nsy, Nsz, Nrz, Nrr (int32); the frequency and the attenuation (float64)
3      the frequencies (float64 × Nfreq)
4      the bearings θ (float64 × Ntheta)
5, 6   source x and y (float64)
7      source depths (float32 × Nsz)
8      receiver depths (float32 × Nrz)
9      receiver ranges, metres (float64 × Nrr)
10 …   the pressure, one record per (frequency, bearing, source depth, receiver depth): Nrr complex64
====== ===========================================================================================

Every size is checked against the bytes there are, so a truncated or foreign file is one clear error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ShadeFile", "FieldFileError", "read_shd"]

MAX_POINTS = 200_000_000
"""More pressure values than this (1.6 GB) is no field hilgate asked for."""


class FieldFileError(ValueError):
    """A BELLHOP output file hilgate cannot read (truncated, another format, absurd sizes)."""


@dataclass(frozen=True)
class ShadeFile:
    title: str
    plot_type: str
    frequency_hz: float
    source_depths: np.ndarray    # (Nsz,)
    receiver_depths: np.ndarray  # (Nrz,)
    ranges: np.ndarray           # (Nrr,) metres
    pressure: np.ndarray         # complex64 (Nsz, Nrz, Nrr), first frequency and bearing

    def transmission_loss_db(self) -> np.ndarray:
        """TL = −20·log10|p| (dB re 1 m); +inf where the field is zero."""
        with np.errstate(divide="ignore"):
            return -20.0 * np.log10(np.abs(self.pressure).astype(np.float64))


def _text(raw: bytes) -> str:
    return raw.decode("latin-1").rstrip(" \x00")


def read_shd(data: bytes) -> ShadeFile:
    """The first frequency and bearing of a shade file's field (hilgate asks BELLHOP for one of each)."""
    if len(data) < 4:
        raise FieldFileError("not a shade file: fewer than 4 bytes")
    words = int(np.frombuffer(data[:4], "<i4")[0])
    recl = 4 * words
    if words < 21 or recl > len(data):  # record 0 holds the length and an 80-character title
        raise FieldFileError(f"not a shade file: record length {words} words for {len(data)} bytes")
    if len(data) < 10 * recl:
        raise FieldFileError(f"truncated shade file: {len(data)} bytes, the header alone takes {10 * recl}")

    def record(i: int) -> bytes:
        return data[i * recl:(i + 1) * recl]

    title = _text(record(0)[4:84])
    plot_type = _text(record(1)[:10])
    counts = np.frombuffer(record(2)[:28], "<i4").astype(np.int64)
    nfreq, ntheta, nsx, nsy, nsz, nrz, nrr = (int(x) for x in counts)
    if min(counts) < 1 or nsz * nrz * nrr > MAX_POINTS or ntheta * nfreq > MAX_POINTS:
        raise FieldFileError(f"not a shade file: sizes {', '.join(str(int(x)) for x in counts)}")
    frequency = float(np.frombuffer(record(2)[28:36], "<f8")[0])
    for n, size, what in ((nfreq, 8, "frequencies"), (ntheta, 8, "bearings"), (nsz, 4, "source depths"),
                          (nrz, 4, "receiver depths"), (nrr, 8, "ranges"), (nrr, 8, "pressure values")):
        if n * size > recl:
            raise FieldFileError(f"not a shade file: {n} {what} do not fit a record of {recl} bytes")
    source_depths = np.frombuffer(record(7)[:4 * nsz], "<f4").astype(np.float64)
    receiver_depths = np.frombuffer(record(8)[:4 * nrz], "<f4").astype(np.float64)
    ranges = np.frombuffer(record(9)[:8 * nrr], "<f8").astype(np.float64)
    need = (10 + nsz * nrz) * recl
    if len(data) < need:
        raise FieldFileError(f"truncated shade file: {len(data)} bytes for {nsz}×{nrz}×{nrr} points ({need})")
    rows = b"".join(data[(10 + i) * recl:(10 + i) * recl + 8 * nrr] for i in range(nsz * nrz))
    pressure = np.frombuffer(rows, "<c8").reshape(nsz, nrz, nrr).copy()
    if not (np.all(np.isfinite(source_depths)) and np.all(np.isfinite(receiver_depths))
            and np.all(np.isfinite(ranges))):
        raise FieldFileError("not a shade file: axes that are not numbers")
    return ShadeFile(title, plot_type, frequency, source_depths, receiver_depths, ranges, pressure)
