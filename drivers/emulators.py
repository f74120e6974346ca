"""The door of the emulated modems: a simulated link's ``emulate:`` opens the emulated device its protocol's
row of the driver table names (:func:`.table.emulator_for`), one module each (:mod:`.evologics_emulator`,
:mod:`.s100_emulator`, :mod:`.m64_emulator`, :mod:`.micromodem_emulator`, :mod:`.unet_emulator`) on the hosts
they share (:mod:`.emulated_modem`: a pty, :mod:`.emulator_pty`, or a TCP port, :mod:`.emulator_tcp`).

Software written for the real modem runs unchanged against the simulation; docs/conformance.md's conformance
tables list what each emulator does and does not emulate.
"""

from __future__ import annotations

from typing import Any

from hilgate.core.endpoint import LinkPort

from .table import emulator_for


class EmulatorDoor:
    """Opens the emulated modem a link's ``emulate:`` asks for, and follows it across reloads."""

    def __init__(self, scheduler: Any):
        self.scheduler = scheduler

    def open(self, port: LinkPort) -> Any:
        options = port.emulate
        if not options:
            return None
        emulator = emulator_for(options["protocol"])(port, options, self.scheduler)
        port.attach(emulator)
        return emulator

    def update(self, handle: Any, port: LinkPort) -> Any:
        if (handle.options if handle is not None else {}) == port.emulate:
            return handle
        self.close(handle, port)
        return self.open(port)

    def close(self, handle: Any, port: LinkPort | None = None) -> None:
        if handle is not None:
            if port is not None:
                port.detach(handle)
            handle.close()
