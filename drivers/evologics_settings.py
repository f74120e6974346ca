"""What an emulated EvoLogics S2C keeps about itself: its settings with their ranges, and its identity.

A real modem refuses a setting out of range instead of taking it (a driver that sets ``AT!AL300``
must see the error in the lab, not at sea), and it keeps its settings in three layers: the factory
defaults (``AT&F`` loads them), the stored profile (``AT&W`` writes it; a reboot, ``ATZ0``, comes
back to it) and the running values.  The ranges are those of ``shared/protocols/evologics-at.md``
("Settings"); the address range depends on ``AM``, so it is checked against the running ``AM``.

The identity (``ATI0``/``ATI1``/``ATI7``, ``AT?MODE``) comes from the modem preset's ``firmware:``
keys, so a driver that checks versions (LSTS DUNE parses ``ATI1`` with a fixed format and wants the
network interpreter, ``NET``) can be satisfied without changing code.

Pure data and checks: no I/O, no clock.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

AM_VALUES = (2, 6, 14, 30, 62, 126, 254)

# name → (factory default, lowest, highest); "AM" is one of AM_VALUES; "AL"/"AR" reach up to AM.
RANGES: dict[str, tuple[int, int, int]] = {
    "AL": (1, 1, 254), "AR": (0, 0, 254), "AM": (254, 2, 254),
    "L": (3, 0, 3), "LC": (0, 0, 1), "G": (0, 0, 1), "C": (0, 0, 3),
    "ZC": (1, 1, 31), "ZP": (500, 50, 5000), "RC": (3, 0, 255), "RT": (1000, 500, 12000), "KO": (0, 0, 255),
    "ZI": (120, 0, 3600), "ZH": (30, 0, 3600), "ZS": (0, 0, 7), "CA": (1500, 1300, 1700), "RI": (3, 0, 255),
    "RP": (0, 0, 1), "ZL": (16384, 1, 1048576), "ZX": (0, 0, 1), "ZF": (0, 0, 1), "ZU": (0, 0, 1),
}


MAX_DIGITS = 10
"""Digits of the widest value a command takes (``ZL`` up to 1 048 576, ``AT!UT`` a 32-bit time).  A longer
number is out of every range: it is read as such without converting it (``int`` of 5 000 digits is a
ValueError, and an offset of 10^30 s an OverflowError further on)."""


def decimal(text: str) -> int | None:
    """The whole number ``text`` spells (ASCII digits, an optional leading ``-``), or None if it spells
    none; beyond :data:`MAX_DIGITS` digits, ±10^MAX_DIGITS, which every range refuses."""
    value = text.strip()
    digits = value[1:] if value.startswith("-") else value
    if not (digits.isascii() and digits.isdigit()):
        return None
    if len(digits) > MAX_DIGITS:
        return -10 ** MAX_DIGITS if value.startswith("-") else 10 ** MAX_DIGITS
    return int(value)


class Settings:
    """The running values, the stored profile and the factory defaults of one emulated modem.

    ``address`` is the link's address, the factory ``AL`` (a modem is delivered with the address its
    lab gave it); ``pool`` the transmit pool, the factory ``ZL``."""

    def __init__(self, address: int, pool: int = 16384):
        self.factory = {name: default for name, (default, _, _) in RANGES.items()}
        if 0 <= address <= 254:
            self.factory["AL"] = address
        self.factory["ZL"] = max(1, min(pool, RANGES["ZL"][2]))
        self.stored = dict(self.factory)
        self.running = dict(self.factory)

    def __getitem__(self, name: str) -> int:
        return self.running[name]

    def __contains__(self, name: str) -> bool:
        return name in self.running

    def problem(self, name: str, text: str) -> str | None:
        """Why ``AT!<name><text>`` is refused (the reason after ``ERROR``), or None."""
        number = decimal(text)
        if number is None:
            return "WRONG FORMAT"
        _, low, high = RANGES[name]
        if name in ("AL", "AR"):
            high = self.running["AM"]
        if name == "AM" and number not in AM_VALUES:
            return "OUT OF RANGE"
        if not low <= number <= high:
            return "OUT OF RANGE"
        return None

    def set(self, name: str, text: str) -> None:
        """Take a value :meth:`problem` accepted."""
        self.running[name] = decimal(text)

    def store(self) -> None:
        """``AT&W``."""
        self.stored = dict(self.running)

    def restore(self) -> None:
        """A reboot (``ATZ0``): the stored profile becomes the running one."""
        self.running = dict(self.stored)

    def factory_defaults(self) -> None:
        """``AT&F``: the factory defaults run (stored only by a following ``AT&W``)."""
        self.running = dict(self.factory)


@dataclass(frozen=True)
class Firmware:
    """What the modem says it is.  ``ATI1`` is printed ``phy: <phy>, mac: v<mac>`` as a real S2C prints
    it (DUNE reads it with ``phy:%*[^0]%[^,], mac:%*[^v]v%s``)."""

    version: str = "1.9"
    phy: str = "0.1.9"
    mac: str = "1.9.0"
    manufacturer: str = "EvoLogics GmbH"
    mode: str = "NET"

    @classmethod
    def from_options(cls, options: Mapping[str, Any] | tuple | None) -> "Firmware":
        values = dict(options or ())
        return cls(**{key: str(value) for key, value in values.items() if key in cls.__dataclass_fields__})

    def information(self, which: str) -> str:
        """``ATI<which>``: 0 (or nothing) the firmware version, 1 the PHY and MAC versions, 7 the maker."""
        if which == "1":
            return f"phy: {self.phy}, mac: v{self.mac}"
        if which == "7":
            return self.manufacturer
        return self.version
