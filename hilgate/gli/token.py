"""The TCP GLI's secret: who may open a link over ``--tcp``.

A link's Unix socket is for the daemon's group (the file system says who may connect); a TCP port is
reachable by anyone on the network, so there an application proves that it holds the daemon's token,
a file only the daemon's group may read (``RUNTIME/tcp.token``, or ``--tcp-token FILE``, 0640).  The
proof is a challenge and a response, not the token itself: on connecting, hilgate sends CHALLENGE with
32 random bytes (a nonce), and the client's HELLO carries ``proof = HMAC-SHA256(token, nonce)`` in
hex.  A sniffer on the lab network sees a nonce and its proof, which no later connection asks for
again (each gets a fresh nonce), and never the token.  What it does not give: secrecy of the frames
and protection against someone who can alter the TCP stream itself (take over an authenticated
connection); for that, tunnel the port (SSH) or use the Zenoh GLI with TLS.

The token is the file's text without surrounding white space: at least 32 printable ASCII characters
(hilgate writes 64 hexadecimal digits, 256 bits, when it creates the file).  Sans-I/O except for the
two functions that read and create the file.
"""

from __future__ import annotations

import errno
import hashlib
import hmac
import os
import secrets
import stat

__all__ = ["TOKEN_FILE", "TokenError", "TokenCheck", "proof", "read_token", "load_or_create"]

TOKEN_FILE = "tcp.token"
NONCE_BYTES = 32
MIN_TOKEN = 32
MAX_TOKEN = 4096


class TokenError(OSError):
    """The token file cannot be used; the message says why and what to do (one line)."""


def proof(token: bytes, nonce: bytes) -> str:
    """What a client answers to ``nonce``: HMAC-SHA256 keyed with the token, in hex."""
    return hmac.new(token, nonce, hashlib.sha256).hexdigest()


class TokenCheck:
    """The daemon's side: a fresh nonce per connection, and whether a proof answers it."""

    def __init__(self, token: bytes, path: str = ""):
        self.token = token
        self.path = path

    @staticmethod
    def challenge() -> bytes:
        return secrets.token_bytes(NONCE_BYTES)

    def verify(self, nonce: bytes, answer: object) -> bool:
        if not isinstance(answer, str) or len(answer) != 64:
            return False
        return hmac.compare_digest(answer.encode("ascii", "replace"), proof(self.token, nonce).encode())


def _parse(data: bytes, path: str) -> bytes:
    token = data.strip()
    if not MIN_TOKEN <= len(token) <= MAX_TOKEN or not all(33 <= byte <= 126 for byte in token):
        raise TokenError(f"{path} is not a token: {MIN_TOKEN} to {MAX_TOKEN} printable ASCII characters "
                         f"without spaces (remove it and hilgate makes a new one)")
    return token


def read_token(path: str) -> bytes:
    """The client's side: the token in ``path`` (a member of the daemon's group may read it)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY)
    except OSError as exc:
        hint = " (the daemon's group may read it: ask to be added)" if isinstance(exc, PermissionError) else ""
        raise TokenError(f"cannot read the TCP GLI token {path}: {exc.strerror or exc}{hint}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise TokenError(f"the TCP GLI token {path} is not a regular file")
        data = os.read(fd, MAX_TOKEN + 64)
    finally:
        os.close(fd)
    return _parse(data, path)


def load_or_create(path: str, group: int | None = None) -> bytes:
    """The daemon's side: the token in ``path``, made (0640, ``group``) if there is none.  An existing
    file must be a regular file of the daemon's user that others cannot read or write: a token
    everyone can read proves nothing, and one someone else wrote is theirs."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o640)
    except FileExistsError:
        return _existing(path)
    except OSError as exc:
        raise TokenError(f"cannot create the TCP GLI token {path}: {exc.strerror or exc}") from None
    try:
        os.fchmod(fd, 0o640)
        if group is not None:
            try:
                os.fchown(fd, -1, group)
            except PermissionError:
                raise TokenError(f"cannot give {path} to group {group}: this user is not a member of it") from None
        token = secrets.token_hex(32).encode()
        os.write(fd, token + b"\n")
    except BaseException:
        os.close(fd)
        os.unlink(path)
        raise
    os.close(fd)
    return token


def _existing(path: str) -> bytes:
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY)
    except OSError as exc:
        what = "a symbolic link" if exc.errno == errno.ELOOP else (exc.strerror or str(exc))
        raise TokenError(f"cannot use the TCP GLI token {path}: {what}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise TokenError(f"the TCP GLI token {path} is not a regular file")
        if info.st_uid != os.geteuid():
            raise TokenError(f"the TCP GLI token {path} belongs to uid {info.st_uid}, not to this user: "
                             f"refusing it (remove it, and hilgate makes its own)")
        if info.st_mode & 0o007:
            raise TokenError(f"the TCP GLI token {path} is readable or writable by others "
                             f"(mode {stat.S_IMODE(info.st_mode):04o}): `chmod 640 {path}`, and make a new one "
                             f"if others may have read it")
        data = os.read(fd, MAX_TOKEN + 64)
    finally:
        os.close(fd)
    return _parse(data, path)
