"""The AT command surface of the emulated EvoLogics S2C (:class:`EvologicsCommands`): one handler per command
in a table, the settings a modem reads and writes, its transmit pool's bounds.  The acoustic side (what goes on
air, delivery reports, what the PHY does) is :class:`.evologics_emulator.EvologicsEmulator`'s."""

from __future__ import annotations

from typing import Any, Callable

from .evologics_codec import Command, ModemCodec
from .evologics_settings import decimal
from .emulator_tcp import TcpClient

BATTERY_V = 24.0  # AT?BV: no battery is modelled; a charged 24 V pack
MAX_TIME_S = 2 ** 32 - 1  # AT!UT: the modem's system time is a 32-bit count of seconds
SEND_MODES = {"*SENDIM": "im", "*SENDIMS": "ims", "*SENDPBM": "pbm", "*SEND": "burst"}


class EvologicsCommands:
    """What an S2C answers its host, as a part of :class:`.evologics_emulator.EvologicsEmulator` (whose state
    it reads and whose ``_send`` it hands accepted messages to): kept apart so that a command is added to a
    table of commands, not among the model's callbacks."""

    def _command(self, host: Any, codec: ModemCodec, command: Command) -> None:
        """One AT command: a handler from :attr:`COMMANDS`, else a setting (``!X``/``@X`` to set,
        ``?X`` to read), else ``ERROR UNKNOWN COMMAND``."""
        def reply(text: str) -> None:
            host.write(codec.reply(command, text))

        handler = self.COMMANDS.get(command.name)
        if handler is not None:
            handler(self, host, codec, command, reply)
            return
        name = command.name
        if name[:1] in ("!", "@") and name[1:] in self.settings:
            problem = self.settings.problem(name[1:], command.args)
            if problem is not None:
                reply(f"ERROR {problem}")
                return
            self._set(name[1:], command.args)
            reply("OK")
        elif name[:1] == "?" and name[1:] in self.settings:
            reply(str(self.settings[name[1:]]))
        else:
            reply("ERROR UNKNOWN COMMAND")

    def _set(self, name: str, text: str) -> None:
        before = self.settings[name]
        self.settings.set(name, text)
        if name == "AL":
            self.port.set_address(self.settings["AL"])
        elif name == "L" and self.settings["L"] != before:
            self._extended(f"SRCLEVEL,{self.settings['L']}")

    # -- the command table: name → handler(self, host, codec, command, reply) -------------------------

    def _ok(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        reply("OK")

    def _data_mode(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        """ATO: the codec has switched to data mode; a modem answers nothing."""

    def _answer(value: Callable[["EvologicsCommands"], str]) -> Callable[..., None]:  # noqa: N805
        """A handler that answers ``value(emulator)``."""
        def handler(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
            reply(value(self))
        return handler

    def _settings(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        lines = [f"{key}: {value}" for key, value in sorted(self.settings.running.items())]
        host.write(codec.reply(command, "\r\n".join(lines) + "\r\n") if codec.data_mode else
                   ("\r\n".join(lines) + "\r\n\r\n").encode())

    def _store(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        self.settings.store()
        reply("OK")

    def _factory(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        self.settings.factory_defaults()
        self.port.set_address(self.settings["AL"])
        reply("OK")

    def _information(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        reply(self.firmware.information(command.args))

    def _set_time(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        """``AT!UT<s>``: the modem's system time (``AT?UT``) reads ``s`` now (seconds, 32 bits)."""
        seconds = decimal(command.args)
        if seconds is None or seconds < 0:
            reply("ERROR WRONG FORMAT")
            return
        if seconds > MAX_TIME_S:
            reply("ERROR OUT OF RANGE")
            return
        self.clock_offset = seconds - self.scheduler.now()
        reply("OK")

    def _reset_counter(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        """``AT@ZD`` / ``AT@ZO``: the drop / overflow counter starts again from 0."""
        if command.name == "@ZD":
            self.dropped = 0
        else:
            self.overflows = 0
        reply("OK")

    def _reset(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        """``ATZ<n>`` as the reference says: 0 reboots (the stored settings run again, every buffer is
        emptied, no answer, a TCP host loses its connection); 1 drops burst data, 3 instant messages,
        4 the whole transmit buffer; 2 clears nothing the emulator holds."""
        which = command.args.strip()
        if which == "0":
            self._clear(("burst", "im", "ims", "pbm"))
            self.settings.restore()
            self.port.set_address(self.settings["AL"])
            self.clock_offset = 0.0
            if isinstance(host, TcpClient):
                host.close()
            else:
                self.codecs[host] = ModemCodec()  # powered on again: command mode, nothing half-read
            return
        if which not in ("1", "2", "3", "4"):
            reply("ERROR WRONG FORMAT")
            return
        self._clear({"1": ("burst",), "2": (), "3": ("im", "ims", "pbm"), "4": ("burst", "im", "ims", "pbm")}[which])
        reply("OK")

    def _sending(self, host: Any, codec: ModemCodec, command: Command, reply) -> None:
        self._send_command(command, reply)

    COMMANDS: dict[str, Callable[..., None]] = {
        "*SENDIM": _sending, "*SENDIMS": _sending, "*SENDPBM": _sending, "*SEND": _sending,
        "O": _data_mode,
        "": _ok, "C": _ok, "H": _ok, "D": _ok, "A": _ok, "N": _ok, "S": _ok, "P": _ok, "&W": _store, "&F": _factory,
        "@CTRL": _ok,
        "?T": _answer(lambda self: str(self.last_ptime_us)),
        "?E": _answer(lambda self: str(self.last_rssi)),
        "?I": _answer(lambda self: str(self.last_integrity)),
        "?V": _answer(lambda self: "0.00"),
        "?P": _answer(lambda self: self._multipath()),
        "?MODE": _answer(lambda self: self.firmware.mode),
        "?PID": _answer(lambda self: str(self.settings["ZS"])),
        "?AL": _answer(lambda self: str(self.port.address)),
        "?S": _answer(lambda self: self._status()),
        "?DI": _answer(lambda self: "EMPTY" if self.pending_ack is None else "DELIVERING"),
        "?PC": _answer(lambda self: str(self.packet_counter)),
        "?CLOCK": _answer(lambda self: str(int(self.scheduler.now()))),
        "?UT": _answer(lambda self: str(int(self.scheduler.now() + self.clock_offset))),
        "!UT": _set_time,
        "?BV": _answer(lambda self: f"{BATTERY_V:.2f}"),
        "?BL": _answer(lambda self: str(self._bitrate())),
        "?BR": _answer(lambda self: str(self._bitrate())),
        "?ZD": _answer(lambda self: str(self.dropped)),
        "?ZO": _answer(lambda self: str(self.overflows)),
        "@ZD": _reset_counter, "@ZO": _reset_counter,
        "&V": _settings,
        "I": _information,
        "Z": _reset,
    }
    del _answer

    def _status(self) -> str:
        """``AT?S`` of the AT interpreter: state, substate, free bytes of the transmit pool."""
        state = "ONLINE NORMAL" if self.pending_ack is None else "ONLINE DELIVERING"
        return f"{state} {self.settings['ZL'] - self._pooled()}"

    def _multipath(self) -> str:
        """``AT?P``: 8 paths ``<t µs> <integrity>`` separated by bare LF (the model has one path)."""
        paths = [f"0 {self.last_integrity if self.received else 0}"] + ["0 0"] * 7
        return "\n".join(paths)

    def _bitrate(self) -> int:
        airtime = self.port.measure.airtime(1)
        return round(8 / airtime) if airtime else 0

    def _pooled(self) -> int:
        return sum(len(frame.real) for frame in self.pool.values())

    def _clear(self, kinds: tuple[str, ...]) -> None:
        """Drop what the transmit buffer holds of ``kinds``: frames not yet on air leave the model's
        FIFO (traced, cause ``cleared``); no report comes for what was awaiting one."""
        frames = [frame for frame in self.pool.values() if frame.meta and frame.meta["kind"] in kinds]
        if frames:
            self.dropped += self.port.withdraw(frames, "cleared")
            for frame in frames:
                self.pool.pop(id(frame), None)
        if "im" in kinds and self.pending_ack is not None:
            self.pending_ack = None
            self.port.state_changed()
        if "burst" in kinds:
            self.bursts.clear()

    def _send_command(self, command: Command, reply) -> None:
        fields = command.fields
        payload = command.payload or b""
        try:
            dst = int(fields[1])
        except (IndexError, ValueError):
            reply("ERROR WRONG FORMAT")
            return
        if not 0 <= dst <= 255:
            reply("ERROR WRONG DESTINATION ADDRESS")
            return
        mode = SEND_MODES[command.name]
        most = self.limits.most(mode)
        if most is not None and len(payload) > most:  # the link's limits: (its preset's), else the S2C's
            reply("ERROR OUT OF RANGE")
            return
        if command.name == "*SEND":
            if self._full(len(payload), reply):
                return
            reply("OK")
            self._send(payload, dst, "burst", True)
            return
        ack = command.name == "*SENDIM" and fields[2] == "ack"
        if command.name == "*SENDIM" and fields[2] not in ("ack", "noack", "force"):
            reply("ERROR WRONG FORMAT")
            return
        if ack and self.pending_ack is not None:
            reply("BUSY DELIVERING")
            return
        if self._full(len(payload), reply):
            return
        reply("OK")
        self._send(payload, dst, {"*SENDIMS": "ims", "*SENDPBM": "pbm"}.get(command.name, "im"), ack)

    def _full(self, size: int, reply) -> bool:
        if self._pooled() + size <= self.settings["ZL"]:
            return False
        self.overflows += 1
        reply("ERROR BUFFER FULL")
        return True
