"""The lab modem: a transparent serial modem (its frames cross as the S100's do, CR LF after each) that a lab
ships as a package of its own.  ``row.py`` is its row of hilgate's driver table (read to check scenes: it
imports nothing that opens a port); ``modem.py`` its driver and its emulated modem."""
