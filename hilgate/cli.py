"""The ``hilgate`` command: its parser, built from the table of commands (:mod:`hilgate.commands`, one module
each), and the one place a command's error becomes an exit status."""

from __future__ import annotations

import argparse
import functools
import sys

from . import __version__
from .commands import TABLE
from .commands.options import EXIT_SCENE
from .scene.yaml_nodes import SceneError

COMMANDS = {command.NAME: command.run for command in TABLE}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hilgate",
        description="Hardware-in-the-loop gateway for underwater communications: dccomms GLI links routed "
                    "to real modems or to a simulated channel.",
    )
    parser.add_argument("--version", action="version", version=f"hilgate {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    for command in TABLE:
        command.add_to(sub)
    return parser


@functools.cache
def _parser() -> argparse.ArgumentParser:
    """The parser ``main`` uses, built once per process: building it costs about 14 ms (argparse looks up
    a translation for every help text), which a process calling ``main`` a thousand times (the trace fuzz
    tests) paid a thousand times.  Parsing leaves it as it was (a default list is copied before an
    appended value goes into it), and every default is a constant."""
    return build_parser()


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args, extra = parser.parse_known_args(argv)
    if extra:
        # `hilgate send LINK --to 2 hello world`: argparse cannot give a '*' positional what follows
        # an option, so the words after it arrive here; anything else unknown is still an error.
        if args.command == "send" and not any(word.startswith("-") for word in extra):
            args.text = [*args.text, *extra]
        else:
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
    from .logsetup import setup_logging

    setup_logging(args.verbose, daemon=args.command in ("run", "emulate"))
    try:
        code = COMMANDS[args.command](args)
        sys.stdout.flush()  # here, not at exit, so that a reader that has gone is noticed below
        return code
    except SceneError as exc:
        print(f"hilgate: {exc}", file=sys.stderr)
        return EXIT_SCENE
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError as exc:
        if _output_closed():
            return _quiet_after_closed_pipe()
        print(f"hilgate: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"hilgate: {exc}", file=sys.stderr)
        return getattr(exc, "exit_status", 1)  # (2 where trying again cannot help: an extra not installed)
    except Exception as exc:  # a client tool's error (GliError, …): one line, no traceback
        from .channel.runner import BellhopError
        from .gli.socket_client import GliError

        if isinstance(exc, (GliError, BellhopError)):
            print(f"hilgate: {exc}", file=sys.stderr)
            return 1
        raise


def _output_closed() -> bool:
    """Whether the reader of stdout (or stderr) has gone, as with ``hilgate pose | head``: the pipe's
    write end then polls as an error.  A broken socket to the daemon is not that, and is reported."""
    import select

    poll = select.poll()
    for stream in (sys.stdout, sys.stderr):
        try:
            poll.register(stream.fileno(), select.POLLOUT)
        except (ValueError, OSError, AttributeError):
            continue
    try:
        return any(events & (select.POLLERR | select.POLLHUP) for _, events in poll.poll(0))
    except OSError:
        return False


def _quiet_after_closed_pipe() -> int:
    """Nothing more can be said where nobody reads: point stdout at /dev/null so that the interpreter's
    last flush cannot complain either, and end as a process killed by SIGPIPE would (128 + 13)."""
    import os

    devnull = os.open(os.devnull, os.O_WRONLY)
    for stream in (sys.stdout, sys.stderr):
        try:
            os.dup2(devnull, stream.fileno())
        except (ValueError, OSError, AttributeError):
            pass
    os.close(devnull)
    return 141


if __name__ == "__main__":
    sys.exit(main())
