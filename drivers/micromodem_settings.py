"""The settings a host reads and writes on the emulated WHOI Micro-Modem (:class:`MicromodemSettings`): its
configuration (``$CCCFQ``/``$CCCFG``, ``$CCALQ``), its clock (``$CCTMS``/``$CCTMQ``, ``$CCCLK``/``$CCCLQ``) and
its hardware lines (``$CCMEC``).  What goes on the channel (cycles, pings, minipackets) and what the model
reports is :class:`.micromodem_emulator.MicromodemEmulator`'s."""

from __future__ import annotations

import datetime

from .micromodem_codec import Sentence, hhmmss

FIRMWARE = "2.0.0"
CONFIG = {"SRC": 0, "AGN": 250, "ASD": 0, "BND": 3, "CST": 1, "CTO": 10, "DTO": 5, "PCM": 0, "REV": 0,
          "RXD": 1, "RXP": 1, "TAT": 50, "TXF": 1, "TXP": 1, "XST": 0}
"""The configuration parameters the emulator keeps (``DTO``: seconds the modem waits for a frame;
``CTO``: seconds a cycle may take in all; ``RXP``, ``TXP``, ``TXF``, ``CST``, ``RXD``: whether it prints
``$CARXP``, ``$CATXP``, ``$CATXF``, ``$CACST``, ``$CARXD``; ``AGN``: the analog gain, 250 is 30 dB).
``$CCCFG,ALL,0`` sets them back to these (the link's address stays)."""


def _iso_time(text: str) -> datetime.datetime | None:
    """An ISO 8601 time as ``$CCTMS`` carries it (``2025-06-06T23:01:23Z``, fractions allowed), in UTC;
    ``acomms`` writes ``…ZZ`` (its time already ends in Z before it adds one), which the modem takes."""
    try:
        when = datetime.datetime.fromisoformat(text.strip().rstrip("Zz") + "+00:00")
    except ValueError:
        return None
    return when if when.tzinfo is not None else when.replace(tzinfo=datetime.timezone.utc)


class MicromodemSettings:
    """What a Micro-Modem's host sets and reads, as a part of :class:`.micromodem_emulator.MicromodemEmulator`
    (whose ``config``, ``port``, ``scheduler``, ``clock_offset`` and ``_say``/``_error`` it uses): kept apart
    so that the modem's cycle and the model's callbacks are not among its settings."""

    def _clock(self) -> str:
        return hhmmss(self._epoch() + self.scheduler.now())

    def _epoch(self) -> float:
        """The modem's clock at model time 0 (UNIX seconds): the daemon's, moved by ``$CCTMS``/``$CCCLK``."""
        return self.scheduler.epoch_ns / 1e9 + self.clock_offset

    def _now(self) -> datetime.datetime:
        return datetime.datetime.fromtimestamp(self._epoch() + self.scheduler.now(), datetime.timezone.utc)

    def _query(self, s: Sentence) -> None:
        name = (s.field(0) or "").upper()
        if name == "ALL":
            for key, value in self.config.items():
                self._say("CACFG", key, value)
        elif name == "INFO":
            self._say("CACFG", "info.firmware_version", FIRMWARE)
        elif name in self.config:
            self._say("CACFG", name, self.config[name])
        else:
            self._error("CCCFQ", 3, f"Unknown parameter {name}")

    def _configure(self, s: Sentence) -> None:
        name = (s.field(0) or "").upper()
        value = s.number(1)
        if name == "ALL" and value == 0:  # factory settings (the link keeps its address)
            self.config = dict(CONFIG, SRC=self.config["SRC"])
            self._say("CACFG", name, value)
            return
        if name not in self.config or value is None:
            self._error("CCCFG", 3, f"Bad parameter {name}")
            return
        if name == "SRC":
            if not 1 <= value <= 254:
                self._error("CCCFG", 4, "SRC out of range")
                return
            self.port.set_address(value)
        self.config[name] = value
        self._say("CACFG", name, value)

    def _api_level(self, s: Sentence) -> None:
        self._say("CAALQ", 0, 11)

    def _set_time(self, s: Sentence) -> None:
        """``$CCTMS,<ISO 8601 time>,<mode>``: the modem's clock reads that time now; ``$CATMS,0,<time>``."""
        when = _iso_time(s.field(0) or "")
        if when is None:
            self._error("CCTMS", 1, "Bad time")
            return
        self._move_clock(when)
        self._say("CATMS", 0, self._iso(self._now()))

    def _query_time(self, s: Sentence) -> None:
        """``$CCTMQ`` → ``$CATMQ,<ISO 8601 time>,<clock source>,<PPS source>`` (the emulator's own clock, no PPS)."""
        self._say("CATMQ", self._iso(self._now()), "RTC", "NONE")

    def _set_clock(self, s: Sentence) -> None:
        """``$CCCLK,yyyy,MM,dd,HH,mm,ss`` (the Micro-Modem 1's clock command) → ``$CACLK`` with the time set."""
        numbers = [s.number(i) for i in range(6)]
        try:
            when = datetime.datetime(*numbers, tzinfo=datetime.timezone.utc)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            self._error("CCCLK", 1, "Bad time")
            return
        self._move_clock(when)
        self._clock_query(s)

    def _clock_query(self, s: Sentence) -> None:
        """``$CCCLQ`` → ``$CACLK,yyyy,MM,dd,HH,mm,ss`` (``libumutil.h``'s answer to the clock query)."""
        now = self._now()
        self._say("CACLK", now.year, now.month, now.day, now.hour, now.minute, now.second)

    def _move_clock(self, when: datetime.datetime) -> None:
        self.clock_offset += when.timestamp() - (self._epoch() + self.scheduler.now())

    @staticmethod
    def _iso(when: datetime.datetime) -> str:
        return when.strftime("%Y-%m-%dT%H:%M:%S.%fZ")

    def _hardware_line(self, s: Sentence) -> None:
        """``$CCMEC,src,dest,line,mode,arg``: this modem's own lines only; echoed ``$CAMEC`` (no line is
        modelled: the echo is all a host sees of it)."""
        numbers = [s.number(i) for i in range(5)]
        if None in numbers or numbers[1] != self.config["SRC"]:
            self._error("CCMEC", 1, "Only the local modem's lines are emulated")
            return
        self._say("CAMEC", *numbers)
