"""The ``hilgate`` command's commands, one module each: a command is its module and one row of :data:`TABLE`.

Each module has ``NAME`` (the word after ``hilgate``), ``add_to(sub)`` (its parser among the subparsers, with
its help) and ``run(args)`` (the exit status).  The table's order is the order ``hilgate --help`` lists them.
Modules that several commands share: :mod:`.options` (argument types), :mod:`.daemon_client` (how a command
reaches the running daemon).
"""

from __future__ import annotations

from . import (app, channel, check, emulate, fit, listen, network, pose, queues, reload, report, run, send, sim,
               status, view)

TABLE = (check, channel, fit, sim, run, emulate, network, queues, status, reload, pose, report, view, app, send,
         listen)
