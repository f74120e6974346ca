"""The lab modem's driver and emulated modem: the S100's line protocol (a transparent byte pipe, frames found
by the link's packet class), under the lab modem's own name in traces and status."""

from hilgate.drivers.s100_emulator import S100Emulator
from hilgate.drivers.s100 import S100Backend


class LabModemBackend(S100Backend):
    """``backend: labmodem``: the driver of a real lab modem on a serial port."""

    kind = "labmodem"


class LabModemEmulator(S100Emulator):
    """``emulate: {protocol: labmodem}``: a lab modem in front of a simulated link, on a pty."""
