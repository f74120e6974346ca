"""The file one frequency's fields are cached in: a format of our own that knows when it is damaged.

numpy's ``.npz`` (a zip) read back a truncated or bit-flipped file as a ``zipfile.BadZipFile`` traceback in
every command, and a flip in an array's header could have been read as other numbers without a word.
Here the whole file is covered by its SHA-256, checked before anything in it is believed, so any damage
(cut short by a full disk or a killed writer, a flipped bit anywhere) is one :class:`CacheFileError`, and
the runner computes the fields again.  Sans-I/O: arrays to bytes and back.

Layout: ``MAGIC``; the header's length (4 bytes, little-endian); the header, JSON: ``[[name, dtype,
shape], …]``; each array's bytes in that order; the SHA-256 of everything before it (32 bytes).
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Mapping

import numpy as np

__all__ = ["CacheFileError", "MAGIC", "encode", "decode"]

MAGIC = b"hilgate BELLHOP fields 1\n"
DTYPES = ("<f8", "<i8")
DIGEST = 32
MAX_HEADER = 1 << 16


class CacheFileError(ValueError):
    """A cache file that is not one this module wrote, or not as it wrote it."""


def encode(arrays: Mapping[str, np.ndarray]) -> bytes:
    """The file's bytes for ``arrays`` (floats as float64, integers as int64)."""
    header, blobs = [], []
    for name, value in arrays.items():
        value = np.asarray(value)
        value = value.astype("<i8" if np.issubdtype(value.dtype, np.integer) else "<f8")
        header.append([name, value.dtype.str, list(value.shape)])
        blobs.append(np.ascontiguousarray(value).tobytes())
    head = json.dumps(header, separators=(",", ":")).encode("ascii")
    body = MAGIC + len(head).to_bytes(4, "little") + head + b"".join(blobs)
    return body + hashlib.sha256(body).digest()


def decode(data: bytes) -> dict[str, np.ndarray]:
    """The arrays of a file :func:`encode` wrote, or :class:`CacheFileError` saying what is wrong."""
    if len(data) < len(MAGIC) + 4 + DIGEST:
        raise CacheFileError(f"truncated: {len(data)} bytes")
    if not data.startswith(MAGIC):
        raise CacheFileError("not a hilgate fields file (another version's, or another file)")
    body, digest = data[:-DIGEST], data[-DIGEST:]
    if hashlib.sha256(body).digest() != digest:
        raise CacheFileError("its checksum does not match: truncated or damaged")
    at = len(MAGIC) + 4
    size = int.from_bytes(body[len(MAGIC):at], "little")
    if size > MAX_HEADER or at + size > len(body):
        raise CacheFileError("its header does not fit the file")
    try:
        header = json.loads(body[at:at + size].decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        raise CacheFileError("its header is not JSON") from None
    at += size
    arrays: dict[str, np.ndarray] = {}
    for entry in header if isinstance(header, list) else [None]:
        if not (isinstance(entry, list) and len(entry) == 3 and isinstance(entry[0], str) and entry[1] in DTYPES
                and isinstance(entry[2], list) and all(isinstance(n, int) and 0 <= n for n in entry[2])):
            raise CacheFileError(f"a header entry that is not [name, dtype, shape]: {str(entry)[:60]}")
        name, dtype, shape = entry
        length = 8 * math.prod(shape)
        if at + length > len(body):
            raise CacheFileError(f"array {name!r} runs past the end of the file")
        arrays[name] = np.frombuffer(body, dtype, math.prod(shape), at).reshape(shape).copy()
        at += length
    if at != len(body):
        raise CacheFileError(f"{len(body) - at} bytes after the last array")
    return arrays
