"""Log lines on stderr: plain on a terminal or in a file, with syslog priorities under systemd's journal.

When systemd connects stderr to the journal it sets ``JOURNAL_STREAM=DEV:INODE`` to that stream.
If stderr is still that stream (not redirected by a shell in between), every line is prefixed with its
``<N>`` syslog priority (sd-daemon(3): ``<3>`` error, ``<4>`` warning, ``<6>`` info, ``<7>`` debug), so
journald stores the level (``journalctl -p warning``), and no timestamp is written: journald adds it.

Levels: the daemon (``hilgate run``, ``hilgate emulate``) and anything under the journal log INFO and
up, so the start-up line, reloads and outages are seen; the one-shot tools (check, sim, status, send…)
log WARNING and up.  ``-v`` adds INFO, ``-vv`` DEBUG; ``$HILGATE_LOG_LEVEL`` (debug, info, warning,
error) sets the default instead, e.g. in ``/etc/hilgate/hilgate.env``.
"""

from __future__ import annotations

import logging
import os
import sys
from typing import TextIO

LEVEL_VARIABLE = "HILGATE_LOG_LEVEL"
LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warning": logging.WARNING, "error": logging.ERROR,
          "critical": logging.CRITICAL}


def syslog_priority(levelno: int) -> int:
    """The sd-daemon(3) priority of a Python logging level (custom levels go to the nearest below)."""
    if levelno >= logging.CRITICAL:
        return 2  # SD_CRIT
    if levelno >= logging.ERROR:
        return 3  # SD_ERR
    if levelno >= logging.WARNING:
        return 4  # SD_WARNING
    if levelno >= logging.INFO:
        return 6  # SD_INFO
    return 7  # SD_DEBUG


def is_journal_stream(stream: TextIO) -> bool:
    """True when ``stream`` is the one systemd connected to the journal (``$JOURNAL_STREAM``).

    The variable is inherited by children whose stderr may go elsewhere (``hilgate status 2>file`` from
    a service's shell), so the stream's device and inode must match, as systemd.exec(5) says."""
    device, _, inode = os.environ.get("JOURNAL_STREAM", "").partition(":")
    try:
        status = os.fstat(stream.fileno())
        return (status.st_dev, status.st_ino) == (int(device), int(inode))
    except (ValueError, OSError, AttributeError):
        return False


class JournalFormatter(logging.Formatter):
    """Every line of a record (a traceback's too) carries the record's ``<N>`` priority: journald
    stores each line as its own entry, and an unprefixed one would default to info."""

    def format(self, record: logging.LogRecord) -> str:
        prefix = f"<{syslog_priority(record.levelno)}>"
        return "\n".join(prefix + line for line in super().format(record).split("\n"))


class TerminalFormatter(logging.Formatter):
    """On a terminal a record first clears the line, so it replaces the daemon's live status line
    (redrawn in place with CR) instead of being appended to it."""

    def format(self, record: logging.LogRecord) -> str:
        return "\r\x1b[K" + super().format(record)


class _Handler(logging.StreamHandler):
    """Ours, so that a second ``setup_logging`` in one process replaces it instead of doubling lines."""


def setup_logging(verbosity: int, daemon: bool = False, stream: TextIO | None = None) -> int:
    """Send log records to ``stream`` (stderr); returns the level chosen.

    ``verbosity`` is the count of ``-v``; ``daemon`` is true for the long-running commands."""
    stream = stream if stream is not None else sys.stderr
    journal = is_journal_stream(stream)
    default = logging.INFO if daemon or journal else logging.WARNING
    asked = os.environ.get(LEVEL_VARIABLE, "").strip().lower()
    if asked in LEVELS:
        default = LEVELS[asked]
    level = min(default, logging.WARNING - 10 * min(verbosity, 2)) if verbosity > 0 else default

    if journal:
        formatter: logging.Formatter = JournalFormatter("%(levelname)s %(name)s: %(message)s")
    else:
        fmt = "%(levelname)s %(name)s: %(message)s"
        if daemon:  # a long run in a terminal or to a file: say when
            fmt = "%(asctime)s.%(msecs)03d " + fmt
        # by name: any stream a caller gives
        tty = getattr(stream, "isatty", lambda: False)() and os.environ.get("TERM", "") != "dumb"
        formatter = (TerminalFormatter if tty else logging.Formatter)(fmt, "%Y-%m-%d %H:%M:%S")

    root = logging.getLogger()
    for handler in [h for h in root.handlers if isinstance(h, _Handler)]:
        root.removeHandler(handler)
    if root.handlers:
        return level  # someone else (pytest's log capture) owns the root logger, as with basicConfig
    handler = _Handler(stream)
    handler.setFormatter(formatter)
    root.addHandler(handler)
    root.setLevel(level)
    if asked and asked not in LEVELS:
        logging.getLogger("hilgate").warning("%s=%r is not one of %s: ignored", LEVEL_VARIABLE, asked,
                                             ", ".join(LEVELS))
    return level
