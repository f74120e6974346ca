"""The lab modem's row of hilgate's driver table, added by the ``hilgate.drivers`` entry point ``labmodem``.

Its options are the S100's (a port, a baud rate, RTS/CTS), and so is what it accepts: pieces of 45 bytes
without flow control; its driver and emulated modem are named as ``module:Class`` and imported only when
the daemon opens a link."""

from hilgate.drivers.table import BY_PTY, Driver, ModemLimits, S100EmulatorOptions, S100Options

LIMITS = ModemLimits("labmodem", piece_bytes=45, flow_control="rtscts", baud=9600)

ROW = Driver("labmodem", "lab modem", S100Options, "labmodem.modem:LabModemBackend",
             "labmodem.modem:LabModemEmulator", reach=BY_PTY, emulator_options=S100EmulatorOptions, limits=LIMITS)
