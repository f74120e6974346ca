"""Real modems and devices behind hilgate (installed as ``hilgate.drivers``): the EvoLogics and S100
drivers, their sans-I/O codecs, the ports they reconnect, the emulated devices, the live pose sources.

:mod:`.table` declares every modem driver once (name, scene options with their checks, how to open it,
its emulator); this package imports nothing, so reading the table costs no driver import.
"""
