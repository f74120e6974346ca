"""A row of the driver table on a bench: its driver and an emulated modem of its own row in one scene, the
driver reaching the modem the way the row declares (``drivers/table.py``'s :class:`Reach`: on a pty, or
on a loopback TCP port), and the cable between them that a test pulls and plugs back (:mod:`cable_kit`).

The driver-table suite (``test_driver_suite.py``) and the start-order test build their scenes here from
the row alone, so a new row gets them by being a row, whatever its driver's keys: a bench is one of the
row's ways (a serial row's pty; the EvoLogics row's pty and ``socket://``; the UnetStack row's TCP port).
Options are read from the row too: each required option the way does not give is a choice (the first for
the near modem, the last for the far one, so an M64 pair is role a and b) or a number (its minimum).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pytest

from cable_kit import PtyCable, TcpCable
from daemon_kit import free_port
from hilgate.drivers.table import DRIVERS, Driver, Reach, emulator_options, scene_options


@dataclass(frozen=True)
class Bench:
    """One row's driver and its emulated modem, reached one of the row's ways."""

    name: str
    reach: Reach

    @property
    def driver(self) -> Driver:
        return DRIVERS[self.name]

    def place(self, directory: Path, tag: str) -> str | int:
        """Where an emulated modem of this bench is: a pty's path in ``directory``, or a free loopback port."""
        return str(directory / tag) if self.reach.way == "pty" else free_port()

    def driver_keys(self, where: str | int, far: bool = False) -> str:
        """The driver link's keys that reach the emulated modem at ``where`` and that the row requires."""
        given = self.reach.driver_options(where)
        chosen = {}
        for key, check, required in scene_options(self.driver):
            if required and key not in given:
                value = _value(check, None, far)
                if value is None:
                    raise AssertionError(f"row {self.name}: no value for its required option {key!r} "
                                         f"(a reach of the row gives it)")
                chosen[key] = value
        return ", ".join(f"{key}: {value}" for key, value in {**given, **chosen}.items())

    def emulate(self, where: str | int, far: bool = False) -> str:
        """The emulated link's ``emulate:`` at ``where`` (the far modem takes the last of a choice: an M64's role)."""
        own = "".join(f", {key}: {_value(check, default, far)}" for key, check, default in emulator_options(self.driver)
                      if check.kind == "choice" and far)
        return f"{{protocol: {self.name}, {self.reach.way}: {where}{own}}}"

    def cable(self, directory: Path, modem: str | int):
        """A cable from a new port (its ``where``, the driver's) to the emulated modem at ``modem``."""
        if self.reach.way == "pty":
            return PtyCable(str(directory / "port"), modem)
        return TcpCable(int(modem))


def _value(check, default, far: bool):
    if check.kind == "choice":
        return check.choices[-1 if far else 0]
    if check.kind in ("integer", "number") and check.minimum is not None:
        return check.minimum if default is None else default
    return default


ROWS = "HILGATE_SUITE_ROWS"
"""``HILGATE_SUITE_ROWS=NAME[,NAME…]``: the benches of those rows only.  A row an installed package adds is
a row of the table in that package's venv: the suite runs against it with that venv's interpreter
(``VENV/bin/python -m pytest tests/test_driver_suite.py``, as ``test_plugin_package.py`` does)."""


def benches() -> list[Bench]:
    """Every way of every row with an emulated modem (of the rows ``HILGATE_SUITE_ROWS`` names, if set)."""
    names = sorted(DRIVERS)
    if os.environ.get(ROWS):
        names = [name.strip() for name in os.environ[ROWS].split(",")]
        absent = [name for name in names if name not in DRIVERS]
        if absent:
            raise LookupError(f"{ROWS}: no row {', '.join(absent)} in this interpreter's driver table "
                              f"({', '.join(sorted(DRIVERS))})")
    return [Bench(name, reach) for name in names if DRIVERS[name].emulator for reach in DRIVERS[name].reach]


def bench_params() -> list:
    """:func:`benches` for ``pytest.mark.parametrize``: a row's first way by its name, another as NAME-WAY."""
    return [pytest.param(bench, id=bench.name if bench.reach == bench.driver.reach[0]
                         else f"{bench.name}-{bench.reach.way}") for bench in benches()]
