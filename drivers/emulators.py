"""Simulated modems that look real: an EvoLogics S2C or a Seatooth S100 on a pseudo-terminal or TCP.

``emulate: {protocol: evologics, pty: /tmp/evo0}`` on a ``backend: sim`` link creates a pty whose
slave is linked at that path (or ``tcp: 9200``, a loopback listener), and answers there like the
modem would, with the link's simulated modem behind it.  Software written for the real modem runs
unchanged against the simulation: ``AT*SENDIM,5,2,ack,hello`` gets ``OK``; the other vehicle's
emulated modem prints ``RECVIM,5,1,2,ack,…`` when the model delivers the frame, with the RSSI,
integrity and radial velocity of :mod:`hilgate.models.link_budget`; its modem answers with an ACK frame
on the channel (:mod:`hilgate.models.acoustic_ack`) and the sender prints ``DELIVEREDIM,2`` when that
ACK has reached it, or ``FAILEDIM,2`` once the ``!RI`` retries went unanswered; ``AT?T`` answers the
one-way time measured from that round trip.  A link with ``usbl:`` prints ``USBLLONG`` and
``USBLANGLES`` (after ``AT@ZU1``) from the simulated geometry after each exchange; settings answer as
a modem does.  Like a modem just powered on, it starts in command mode (``ATO`` enters data mode,
``+++AT`` escapes work there). Enough of the S2C's command surface is there for field
drivers that poll and check it (LSTS DUNE's task: ``AT?MODE``, ``ATI1``, ``AT?CLOCK``, ``AT?P``,
``SENDEND``, burst reports); the conformance table of docs/modems.md lists what is and is not emulated.

The S100 emulator is the byte pipe the real one is, on a serial line paced as the real one: frames
of the link's packet class followed by CR LF in, the same bytes out on the other side; other bytes
pass through as they are (:class:`S100Emulator`).
"""

from __future__ import annotations

import itertools
import logging
import os
import socket
import stat
import tty
from abc import ABC, abstractmethod
from typing import Any, Callable

from hilgate.core.backend import AppFrame, PhyEvent
from hilgate.core.endpoint import TAKEN, LinkPort
from hilgate.core.outputs import OutputError, pty_link_problem_at
from hilgate.core.safepath import PathError, open_parent
from hilgate.core.packets import BROADCAST, Decoded, Raw
from hilgate.core.streams import Connection, Listener

from .evologics_codec import BadCommand, Command, Data, ModemCodec
from .evologics_settings import Firmware, Settings, decimal
from .s100_codec import (CRLF, IDLE_S, PIECE, TERMINATOR, FrameHunter, InputBuffer, Notice, SerialLine, Skipped,
                         wire_class)
from .table import ModemLimits, emulator_for, limits_for

log = logging.getLogger(__name__)

FOREVER = 1 << 30  # !RI255: retry for ever
BATTERY_V = 24.0  # AT?BV: no battery is modelled; a charged 24 V pack
MAX_TIME_S = 2 ** 32 - 1  # AT!UT: the modem's system time is a 32-bit count of seconds
MAX_TCP_CLIENTS = 8  # an emulated modem's TCP port: hosts at once (a real S2C serves a few on its port)
TCP_OUTPUT_CAP = 256 * 1024  # answers kept for a TCP host that does not read (beyond: not sent)
LINE_AHEAD_S = 2.0  # the emulated S100 reads at most this far ahead of its serial line (then the writer waits)
WATCH_S = 0.01  # without flow control, the loop looks at its inputs at least this often (wall seconds)
HANDOVER_CAP_S = 0.25  # the kernel's hand-over delay an emulated S100 allows for at most (wall seconds)
HANDOVER_FIXED_S = 0.05  # …and allows for when the host cannot say how long its tasks waited (no PSI)
SEND_MODES = {"*SENDIM": "im", "*SENDIMS": "ims", "*SENDPBM": "pbm", "*SEND": "burst"}


class PtyHost:
    """The modem side of a pseudo-terminal; the slave end is linked at ``path`` for the application."""

    def __init__(self, path: str, scheduler: Any, on_data, name: str, group: int | None = None):
        self.path = path
        self.scheduler = scheduler
        self.on_data = on_data
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line discipline: a serial line carries bytes
        # /dev/pts/N is the daemon user's with group tty, 0620: give it to the daemon's group instead,
        # so the lab's software (members of that group, as for the GLI) can open it, and nobody else
        try:
            os.fchown(self.slave, -1, os.getegid() if group is None else group)
            os.fchmod(self.slave, 0o660)
        except OSError as exc:
            log.warning("%s: cannot give the pty to the daemon's group: %s", name, exc)
        os.set_blocking(self.master, False)
        self.target = os.ttyname(self.slave)
        try:
            self._link(path)
        except OSError:
            for fd in (self.master, self.slave):
                os.close(fd)
            raise
        scheduler.add_reader(self.master, self._readable)
        self.paused = False
        log.info("%s: emulated modem at %s (%s)", name, path, os.ttyname(self.slave))

    def _link(self, path: str) -> None:
        """Link the pty at ``path``: where nothing is, or over a pty link a previous run left (the scene
        loader checked it too; the file system may have changed since).  symlink(2) never replaces, so
        something that appears meanwhile is refused, not removed.  The directory is reached once, without
        another user's links (:mod:`hilgate.core.safepath`), and kept open: the link is made, read and
        removed by name in it, so nobody can point the removal at stop at another directory."""
        try:
            self.directory, self.name = open_parent(path)
        except PathError as exc:
            raise OutputError(str(exc) if not exc.missing else f"cannot make the pty link {path}: {exc}") from None
        try:
            problem = pty_link_problem_at(self.directory, self.name, path)
            if problem is not None:
                raise OutputError(problem)
            try:  # a previous run's pty link (the look above): made anew
                if stat.S_ISLNK(os.stat(self.name, dir_fd=self.directory, follow_symlinks=False).st_mode):
                    os.unlink(self.name, dir_fd=self.directory)
            except FileNotFoundError:
                pass
            try:
                os.symlink(self.target, self.name, dir_fd=self.directory)
            except FileExistsError:
                raise OutputError(f"{path} appeared while the emulated modem's pty link was being made: "
                                  f"not replacing it") from None
        except BaseException:
            os.close(self.directory)
            raise

    def pause(self) -> None:
        """Stop reading: what the application writes waits in the kernel's pty buffer, and once that is
        full its writes block, as on a real serial port that carries bytes only at its baud rate."""
        if not self.paused:
            self.paused = True
            self.scheduler.remove_reader(self.master)

    def resume(self) -> None:
        if self.paused:
            self.paused = False
            self.scheduler.add_reader(self.master, self._readable)

    def _readable(self) -> None:
        try:
            data = os.read(self.master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return  # nobody has the slave open: nothing to read
        if data:
            self.on_data(self, data)

    def write(self, data: bytes) -> None:
        try:
            os.write(self.master, data)
        except (BlockingIOError, OSError) as exc:
            log.debug("pty %s: %s", self.path, exc)

    def close(self) -> None:
        self.paused = True
        self.scheduler.remove_reader(self.master)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass
        try:
            if os.readlink(self.name, dir_fd=self.directory) == self.target:  # only our own: not one put there since
                os.unlink(self.name, dir_fd=self.directory)
        except OSError:
            pass
        try:
            os.close(self.directory)
        except OSError:
            pass


class TcpHosts:
    """A loopback listener; each client is a host with its own protocol state.

    At most :data:`MAX_TCP_CLIENTS` at once (each holds a codec and up to :data:`TCP_OUTPUT_CAP` bytes of
    answers it has not read).  When a host connects to a full port, the host that has been quiet longest
    (connected or last heard from earliest) is closed to make room, and counted in :attr:`evicted`:
    refusing the newcomer instead let eight connections that never said anything keep the lab's own
    software out for as long as they stayed (issue 37).  A host that talks keeps its place; a stranger
    can still close one that only listens, by connecting eight times, as it could unplug a real modem's
    Ethernet cable: the port is as open as a real modem's (docs/security.md says how to restrict it)."""

    def __init__(self, port: int, scheduler: Any, on_data, on_connect, name: str, host: str = "127.0.0.1",
                 on_disconnect=None):
        self.scheduler = scheduler
        self.on_data = on_data
        self.on_connect = on_connect
        self.on_disconnect = on_disconnect
        self.name = name
        self.clients: set[_TcpClient] = set()
        self.evicted = 0
        self.heard = itertools.count()  # an order of who was heard from last (no clock needed)
        sock = socket.create_server((host, port))
        sock.setblocking(False)
        self.listener = Listener(sock, scheduler, self._accept)
        log.info("%s: emulated modem on tcp://%s:%d", name, host, port)

    def _accept(self, sock: socket.socket) -> None:
        if len(self.clients) >= MAX_TCP_CLIENTS:
            # hosts that left but whose end of file the loop has not read yet hold no place: a host that
            # reconnects at once does not push out another for its own old connection (seen on a loaded host)
            for client in [c for c in self.clients if c.connection.hung_up()]:
                client.connection.close()
        if len(self.clients) >= MAX_TCP_CLIENTS:
            quiet = min(self.clients, key=lambda c: c.last_heard)
            self.evicted += 1
            if self.evicted & (self.evicted - 1) == 0:  # the 1st, 2nd, 4th, 8th…: a flood costs a few lines
                log.warning("%s: emulated modem closed the TCP host quiet longest to serve a new one: %d "
                            "connected already (%d closed so far)", self.name, len(self.clients), self.evicted)
            quiet.close()
        client = _TcpClient(self, sock)
        self.clients.add(client)
        self.on_connect(client)

    def close(self) -> None:
        for client in list(self.clients):
            client.connection.close()
        self.listener.close()


class _TcpClient:
    def __init__(self, hosts: TcpHosts, sock: socket.socket):
        self.hosts = hosts
        self.last_heard = next(hosts.heard)
        self.connection = Connection(sock, hosts.scheduler, self._data, self._closed, max_buffer=TCP_OUTPUT_CAP)

    def _data(self, data: bytes) -> None:
        self.last_heard = next(self.hosts.heard)
        self.hosts.on_data(self, data)

    def _closed(self) -> None:
        self.hosts.clients.discard(self)
        if self.hosts.on_disconnect is not None:
            self.hosts.on_disconnect(self)  # its protocol state goes with it (1 500 clients leave nothing)

    def write(self, data: bytes) -> None:
        self.connection.write(data)

    def close(self) -> None:
        self.connection.close()


def _open_hosts(spec: dict, scheduler: Any, on_data, on_connect, name: str, on_disconnect=None):
    if "pty" in spec:
        host = PtyHost(spec["pty"], scheduler, on_data, name)
        on_connect(host)
        return host
    return TcpHosts(int(spec["tcp"]), scheduler, on_data, on_connect, name, on_disconnect=on_disconnect)


class EmulatedModem(ABC):
    """What every emulated modem is: an endpoint of kind ``emulator`` on its link's port, and the hosts its
    ``emulate:`` names (a pty, or the clients of a TCP port).  Those that speak a line protocol give each
    host a codec of its own (the modem side of the protocol, sans I/O: ``codec``), made when the host
    connects and dropped when it leaves; a subclass opens the hosts (:meth:`_serve_hosts`) once its own
    state is set, since a pty is a host at once."""

    kind = "emulator"
    assumes_busy = False  # (hilgate.core.endpoint.Endpoint.assumes_busy: an emulated modem is told BUSY by the link)
    codec: Any = None

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        self.port = port
        self.options = spec
        self.scheduler = scheduler

    def _serve_hosts(self) -> None:
        self.codecs: dict[Any, Any] = {}
        self.hosts = _open_hosts(self.options, self.scheduler, self._on_data, self._on_connect, self.port.id,
                                 lambda host: self.codecs.pop(host, None))

    def _on_connect(self, host: Any) -> None:
        self.codecs[host] = self.codec()

    @abstractmethod
    def _on_data(self, host: Any, data: bytes) -> None:
        """``host``'s bytes (a pty or a TCP client), to its codec."""

    def _codec_of(self, host: Any) -> Any:
        """``host``'s codec (made here too: a TCP client's first bytes may come before its connect is seen)."""
        codec = self.codecs.get(host)
        if codec is None:
            codec = self.codecs[host] = self.codec()
        return codec

    def _to_hosts(self, line: bytes) -> None:
        """``line`` to every host (what a modem prints on its one serial line, to each client on TCP)."""
        for host in list(self.codecs):
            host.write(line)

    def close(self) -> None:
        self.hosts.close()


class EvologicsEmulator(EmulatedModem):
    """An EvoLogics S2C modem in front of a simulated link.

    Its settings (:mod:`.evologics_settings`) are range-checked and kept as running, stored and factory
    values; ``AT!AL`` moves the link to the new address in the simulation.  Its transmit pool holds what
    it accepted until the model's transmission of it ends (``ERROR BUFFER FULL`` beyond ``ZL`` bytes;
    ``ATZ1``/``ATZ3``/``ATZ4`` empty it).  With ``AT@ZX1`` it reports what the simulated PHY does
    (SENDSTART/SENDEND, RECVSTART/RECVEND/RECVFAILED, BITRATE, SRCLEVEL) at the model's times."""

    codec = ModemCodec

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        super().__init__(port, spec, scheduler)
        self.firmware = Firmware.from_options(spec.get("firmware"))
        self.settings = Settings(port.address)
        self.pending_ack: AppFrame | None = None
        self.bursts: dict[int, AppFrame] = {}  # packet counter → burst awaiting its report
        self.packet_counter = 0
        self.pool: dict[int, AppFrame] = {}  # id → accepted frames whose transmission has not ended
        self.receiving: dict[int, float] = {}  # id of a frame arriving → when its arrival began
        self.dropped = 0     # AT?ZD: frames the modem dropped (buffer cleared, no remote address)
        self.overflows = 0   # AT?ZO: frames refused because the transmit pool was full
        self.clock_offset = 0.0  # AT!UT
        self.last_ptime_us = 0
        self.last_rssi = -50
        self.last_integrity = 150
        self.last_velocity = 0.0
        self.received = False  # AT?P answers zeros until something was received
        self._serve_hosts()

    @property
    def limits(self) -> ModemLimits:
        """What this modem accepts: the link's ``limits:`` (read anew, a reload may change them)."""
        return limits_for("evologics", self.port.limits)

    # -- host → modem -------------------------------------------------------------------------------

    def _on_data(self, host: Any, data: bytes) -> None:
        codec = self._codec_of(host)
        for event in codec.receive_data(data):
            match event:
                case Command():
                    self._command(host, codec, event)
                case BadCommand(reason=reason):
                    host.write(codec.error(None, reason))
                case Data(payload=payload):
                    self._raw_data(payload)

    def _raw_data(self, payload: bytes) -> None:
        """Burst data in data mode goes to ``AR``; with ``AR`` 0 a modem cannot send it (dropped, counted
        in ``AT?ZD`` and traced), nor beyond the transmit pool (``AT?ZO``)."""
        remote = self.settings["AR"]
        most = self.limits.most("burst") or len(payload) or 1
        for start in range(0, len(payload), most):
            piece = payload[start:start + most]
            if remote == 0:
                self.dropped += 1
                self.port.lost("no_remote_address", len(piece), src="app")
            elif self._pooled() + len(piece) > self.settings["ZL"]:
                self.overflows += 1
                self.port.lost("buffer_full", len(piece), src="app")
            else:
                self._send(piece, remote, "burst", True)

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

    def _answer(value: Callable[["EvologicsEmulator"], str]) -> Callable[..., None]:  # noqa: N805
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
            if isinstance(host, _TcpClient):
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
        airtime = self.port.airtime(1)
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

    def _send(self, payload: bytes, dst: int, kind: str, ack: bool) -> None:
        frame = AppFrame(payload, payload, Raw(), 0, self.port.address, dst, self.scheduler.now())
        frame.meta = {"kind": kind, "ack": ack}
        if kind == "burst":  # AT?PC numbers it
            self.packet_counter += 1
            frame.meta["pc"] = self.packet_counter
        if dst != BROADCAST and (ack or kind == "burst"):
            # the receiving modem answers on the channel (hilgate.models.acoustic_ack); an IM retries !RI
            # times (255: for ever), a burst !RC times (a burst is acknowledged whatever ``ack`` says);
            # the model's outcome is the report
            if kind == "burst":
                frame.ack_retries = int(self.settings["RC"])
            else:
                retries = int(self.settings["RI"])
                frame.ack_retries = FOREVER if retries == 255 else retries
            frame.on_acknowledged = self._acknowledged
            if kind == "burst":
                self.bursts[frame.meta["pc"]] = frame
            else:
                self.pending_ack = frame
        self.pool[id(frame)] = frame
        self.port.send(frame)

    # -- delivery reports -------------------------------------------------------------------------------

    def _awaited(self, frame: AppFrame) -> bool:
        if frame is self.pending_ack:
            return True
        pc = (frame.meta or {}).get("pc")
        return pc is not None and self.bursts.get(pc) is frame

    def _acknowledged(self, frame: AppFrame, delivered: bool, tau: float | None) -> None:
        """The model's report on an ``ack`` IM or a burst: its ACK came back (``tau``: the one-way time
        the modem measured from the round trip), or the last retry went unanswered."""
        if not self._awaited(frame):
            return  # (cleared by ATZ meanwhile: no report, as on a modem)
        if frame is self.pending_ack:
            self.pending_ack = None
        else:
            del self.bursts[frame.meta["pc"]]
        if delivered and tau is not None:
            self.last_ptime_us = round(tau * 1e6)
        self._notify(self._delivery_line(frame, delivered))
        if delivered:
            self._usbl(frame.dst, self.scheduler.now(), tau)
        self.port.state_changed()

    @staticmethod
    def _delivery_line(frame: AppFrame, delivered: bool) -> str:
        """The one place a delivery decision becomes a report: ``DELIVEREDIM,<dst>``/``FAILEDIM,<dst>``
        for an instant message, ``DELIVERED,<pc>,<dst>``/``FAILED,<pc>,<dst>`` for a burst."""
        if (frame.meta or {}).get("kind") == "burst":
            return f"{'DELIVERED' if delivered else 'FAILED'},{frame.meta['pc']},{frame.dst}"
        return f"{'DELIVEREDIM' if delivered else 'FAILEDIM'},{frame.dst}"

    def _notify(self, text: str, payload: bytes | None = None) -> None:
        for host, codec in list(self.codecs.items()):
            host.write(codec.notify_line(text, payload))

    def _extended(self, text: str) -> None:
        """An extended notification, printed only after ``AT@ZX1``."""
        if self.settings["ZX"]:
            self._notify(text)

    # -- what the simulated PHY does (extended notifications, the transmit pool) ----------------------

    def phy(self, event: PhyEvent) -> None:
        frame = event.frame
        if frame is None:
            return  # background traffic and MAC frames: nothing a host of this modem sent or will read
        if event.kind == "tx":
            if id(frame) not in self.pool:
                return
            kind = frame.meta["kind"]
            duration_us = round((event.end - event.start) * 1e6)
            if kind == "burst":
                self._extended(f"BITRATE,local,{self._bitrate()}")
            self._extended(f"SENDSTART,{frame.dst},{kind},{duration_us},{round((event.start - frame.t0) * 1e6)}")
            self.scheduler.at(event.end, self._sent, frame, duration_us)
            return
        if event.dst != self.port.address and event.dst != BROADCAST:
            return
        if event.kind == "rx_start":
            self.receiving[id(frame)] = event.start
            self._extended("RECVSTART")
            return
        start = self.receiving.pop(id(frame), None)
        duration_us = round((event.end - start) * 1e6) if start is not None else 0
        rssi, integrity = self._signal(frame.src, event.end)
        if event.cause is None:
            self._extended(f"RECVEND,{round(event.end * 1e6)},{duration_us},{rssi},{integrity}")
        else:
            self._extended(f"RECVFAILED,0.00,{rssi},0")

    def _sent(self, frame: AppFrame, duration_us: int) -> None:
        """The model's transmission of ``frame`` ended: it leaves the pool; ``SENDEND`` (a host waits for
        it to free the modem after a ``noack`` message)."""
        if self.pool.pop(id(frame), None) is not None:
            now = self.scheduler.now()
            self._extended(f"SENDEND,{frame.dst},{frame.meta['kind']},{round(now * 1e6)},{duration_us}")

    def _signal(self, src: int, t: float) -> tuple[int, int]:
        """RSSI (dB) and integrity of a frame from ``src`` heard at ``t`` (hilgate.models.link_budget)."""
        heard = self.port.reception_from(src, t)
        if heard is None:  # a sender the model does not know (or out of range): nothing measured
            return self.last_rssi, 0
        return heard.rssi_db, heard.integrity

    # -- medium → host ----------------------------------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        meta = frame.meta or {}
        kind = meta.get("kind", "im")
        payload = frame.real
        heard = self.port.reception_from(frame.src, t)
        d = heard.distance_m if heard is not None else 0.0
        if heard is not None:  # the model's measurements (hilgate.models.link_budget), not constants
            self.last_rssi, self.last_integrity, self.last_velocity = heard.rssi_db, heard.integrity, heard.velocity_mps
        velocity = self.last_velocity
        airtime = self.port.airtime(len(frame.real)) or 0.0  # the whole frame on air
        duration_us = round(airtime * 1e6)
        ptime_us = round((self.port.delay_from(frame.src, t) or 0.0) * 1e6)  # the channel's: BELLHOP's in water
        self.received = True
        if kind == "burst":
            self._extended(f"BITRATE,remote,{self._bitrate()}")
        for host, codec in list(self.codecs.items()):
            if kind == "burst":
                if codec.data_mode:
                    host.write(payload)
                    continue
                bit_time = self.port.airtime(1)
                bitrate = round(8 / bit_time) if bit_time else 0
                text, body = ModemCodec.recv_burst(frame.src, frame.dst, payload, bitrate,
                                                   self.last_rssi, self.last_integrity, ptime_us, velocity)
            elif kind == "ims":
                text = (f"RECVIMS,{len(payload)},{frame.src},{frame.dst},{round(t * 1e6)},{duration_us},"
                        f"{self.last_rssi},{self.last_integrity},{velocity:.2f},")
                body = payload
            elif kind == "pbm":
                text = (f"RECVPBM,{len(payload)},{frame.src},{frame.dst},{duration_us},{self.last_rssi},"
                        f"{self.last_integrity},{velocity:.2f},")
                body = payload
            else:
                text, body = ModemCodec.recvim(frame.src, frame.dst, payload, bool(meta.get("ack")), duration_us,
                                               self.last_rssi, self.last_integrity, velocity)
            host.write(codec.notify_line(text, body))
        self._usbl(frame.src, t, ptime_us / 1e6, t - airtime)
        return TAKEN

    def _usbl(self, address: int, t: float, tau: float | None, measured: float | None = None) -> None:
        """After an exchange with ``address``: a USBL link with ``AT@ZU1`` prints its fix of that modem."""
        if not self.settings["ZU"]:
            return
        found = self.port.usbl_fix(address, t)
        if found is None:
            return
        heard, fix = found
        for line in usbl_lines(heard, fix, address, t, t if measured is None else measured,
                               tau if tau is not None else 0.0):
            self._notify(line)

    def state(self, ready: bool) -> None:
        """A modem says nothing when its transmit buffer drains (AT?ZS / BUSY answers say it)."""

    @property
    def busy(self) -> bool:
        return self.pending_ack is not None


def usbl_lines(heard: Any, f: Any, address: int, t: float, measured: float, tau: float) -> list[str]:
    """``USBLLONG`` and ``USBLANGLES`` of a fix ``f`` (``models.usbl.UsblFix``) for a reception ``heard``
    (``models.link_budget.Reception``), in the reference's field order and the precision real modems print
    (times to the µs, metres and radians to 4 decimals)."""
    x, y, z = f.local
    e, n, u = f.enu
    roll, pitch, yaw = f.orientation
    common = f"{t:.6f},{measured:.6f},{address}"
    return [
        f"USBLLONG,{common},{x:.4f},{y:.4f},{z:.4f},{e:.4f},{n:.4f},{u:.4f},{roll:.4f},{pitch:.4f},{yaw:.4f},"
        f"{round(tau * 1e6)},{heard.rssi_db},{heard.integrity},{f.accuracy_m:.4f}",
        f"USBLANGLES,{common},{f.local_bearing:.4f},{f.local_elevation:.4f},{f.bearing:.4f},{f.elevation:.4f},"
        f"{roll:.4f},{pitch:.4f},{yaw:.4f},{heard.rssi_db},{heard.integrity},{f.accuracy_m:.4f}",
    ]


class _S100Host:
    """What the emulated S100 keeps for one host: its frame hunter, both directions of its serial
    line, its 45-byte input buffer (without flow control) and the bytes that are no frame yet."""

    def __init__(self, emulator: "S100Emulator"):
        self.hunter = FrameHunter(emulator.port.packet)
        self.line_in = SerialLine(emulator.baud, emulator.speed)
        self.line_out = SerialLine(emulator.baud, emulator.speed)
        self.buffer: InputBuffer | None = None  # made with the first bytes (the link's modem may come later)
        self.other = bytearray()  # bytes that are no frame of the link's class: passed on as they are
        self.waiting: tuple[Decoded, bytes] | None = None  # a frame and the part of its CR LF still to come
        self.after_frame = False  # the last thing sent was a frame: a CR LF now is its own (the far S100 adds one)
        self.judged_until = float("-inf")  # the latest arrival the input buffer was judged with (its own line)
        self.read_at = float("-inf")  # when bytes were last read from this host, and the host's stall then
        self.stall_then: float | None = None
        self.idle_timer = None
        self.resume_timer = None  # while reading is paused: when the line has room again


class S100Emulator(EmulatedModem):
    """A Seatooth S100 in front of a simulated link: a transparent byte pipe on a serial line.

    - **The line.** A pty takes no time per byte; the real line takes 10 bits per byte (8N1) at the
      scene's ``baud`` (default 9600, as dccomms' bridge).  Each byte the host writes is taken to
      arrive when the real line would bring it (:class:`SerialLine`), and a frame goes to the channel
      when the CR LF that ends it is in (as the real modem sends a packet; without a CR LF, after
      :data:`IDLE_S`); received frames (+ CR LF) reach the host when their last byte would.
    - **45 bytes without flow control** (``rtscts: false``, the default): the modem holds at most 45
      bytes and sends them at the air bitrate; bytes that arrive when it is full are lost, counted and
      traced (``cause: overflow``) (:class:`InputBuffer`).  With ``rtscts: true`` the modem stops the host
      instead: nothing is lost.
    - **Frames and other bytes.** Frames of the link's packet class (hunted by preamble, length and CRC)
      go on air as one frame each, as the other doors of the link see them, and come out followed by
      CR LF.  Bytes that are no such frame (text, a frame with a bad CRC, a ``+++`` line) are passed
      through as a raw frame, CR LF included, as a real S100 would carry them: when a CR LF or a frame
      ends them, after :data:`IDLE_S` without bytes, or (without flow control) 45 bytes at a time; the
      far emulated S100 writes them unchanged.  So a frame longer than 45 bytes without flow control
      crosses as 45-byte pieces, as on the real modem, and the far host's framing joins them again.
    - **A busy host loses nothing a real modem would keep.**  The emulator sees a byte when the kernel hands
      it over, not when the host wrote it: a machine that froze for a moment (a preemption, a virtual
      machine's host busy with its disk) hands over two paced pieces at once, which on a real line came
      200 ms apart.  So the 45 bytes are judged against the most favourable arrival the loop cannot rule
      out: the bytes of one read may have come at any time since the loop last looked
      (:meth:`~hilgate.core.realtime.RealtimeScheduler.input_window`; the loop is asked to look at
      least every :data:`WATCH_S`), or the kernel held them (its pty worker waits for a CPU like any
      task: at most as long as the host's tasks waited since the last read, :mod:`hilgate.core.stall`,
      capped at :data:`HANDOVER_CAP_S`), spread at most as the line allows.  On a quiet host that is
      the line's own timing; a host that writes more than the modem holds at once loses the bytes the
      modem could not hold, and each overflow's trace line says the window it was judged with
      (``window``).  Frames go to the channel at the times the line carries them from when they were
      read, as before.
    """

    busy = False
    phy = None  # (no PHY reports: hilgate.core.endpoint.Endpoint.phy)

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        super().__init__(port, spec, scheduler)
        self.baud = int(spec.get("baud", 9600))
        self.rtscts = bool(spec.get("rtscts", False))
        self.speed = scheduler.speed  # line times are wall-clock seconds
        self.piece = limits_for("s100", port.limits).piece_bytes or PIECE  # held without flow control (limits:)
        self.states: dict[Any, _S100Host] = {}
        # (with flow control nothing is judged: the loop need not look more often than it does)
        self.watch = None if self.rtscts else scheduler.watch_inputs(WATCH_S)
        self.hosts = _open_hosts(spec, scheduler, self._on_data, self._on_connect, port.id)

    def _on_connect(self, host: Any) -> None:
        self.states[host] = _S100Host(self)

    # -- host → channel ---------------------------------------------------------------------------------

    def _on_data(self, host: Any, data: bytes) -> None:
        state = self.states.get(host)
        if state is None:
            state = self.states[host] = _S100Host(self)
        now = self.scheduler.now()
        line = state.line_in
        start = max(now, line.free_at)
        line.send(now, len(data))
        bt = line.byte_time
        arrivals = [start + (i + 1) * bt for i in range(len(data))]
        if state.buffer is None and not self.rtscts:
            airtime = self.port.airtime(1)
            if airtime:
                state.buffer = InputBuffer(1.0 / airtime, self.piece)  # drained at the air bitrate
        if state.buffer is not None:
            window = self._window(state, now)
            fits = state.buffer.accept(*self._judged_arrival(state, now, window, len(data), bt))
            lost = fits.count(False)
            if lost:
                self.port.lost("overflow", lost, src="app", window=window)
                data = bytes(b for b, kept in zip(data, fits) if kept)
                arrivals = [t for t, kept in zip(arrivals, fits) if kept]
        if state.waiting is not None:
            # a frame whose chunk ended before its CR LF: it goes when the CR LF is in (or at once if
            # something else came instead)
            frame, need = state.waiting
            state.waiting = None
            done = len(need) if data.startswith(need) else 0
            self.scheduler.at(arrivals[done - 1] if done else start, self._event, state, frame)
        hunter = state.hunter
        base = hunter.fed  # the stream offset of data[0]
        for event, end in hunter.receive_data_at(data):
            local = end - base
            at = arrivals[local - 1] if local > 0 else start
            if isinstance(event, Decoded) and local > 0:
                # the S100 sends a packet when the CR LF that ends it is in, not at the frame's last byte
                after = data[local:local + 2]
                if after == CRLF:
                    at = arrivals[local + 1]
                elif CRLF.startswith(after):  # the chunk ends inside the frame's CR LF, or right after it
                    state.waiting = (event, CRLF[len(after):])
                    continue
            self.scheduler.at(at, self._event, state, event)
        piece = self.piece
        while state.buffer is not None and hunter.held >= piece:
            # without flow control the modem sends what it holds once it has 45 bytes, CR LF or not: a
            # longer frame goes on air in 45-byte pieces (the far host's own framing joins them again)
            local = hunter.consumed + piece - base
            self.scheduler.at(arrivals[local - 1] if local > 0 else start, self._piece, state, hunter.take(piece))
        self.scheduler.cancel(state.idle_timer)
        state.idle_timer = self.scheduler.at(line.free_at + IDLE_S * self.speed, self._idle, state)
        self._pace(host, state, now)

    def _window(self, state: _S100Host, now: float) -> float:
        """How long before ``now`` (model seconds) the bytes read now may have been written: what the loop
        cannot rule out, and what the kernel may have held them meanwhile (0 in virtual time)."""
        scheduler = self.scheduler
        stall = scheduler.host_stall()
        if stall is None:
            held = HANDOVER_FIXED_S * self.speed
        elif state.stall_then is None:
            held = 0.0
        else:
            held = min((stall - state.stall_then) * self.speed, now - state.read_at, HANDOVER_CAP_S * self.speed)
        state.stall_then, state.read_at = stall, now
        return scheduler.input_window() + held

    @staticmethod
    def _judged_arrival(state: _S100Host, now: float, window: float, size: int,
                        bt: float) -> tuple[float, int, float]:
        """When ``size`` bytes read at ``now`` are taken to have come, for the 45-byte buffer only: from as
        early as ``window`` allows (not before the bytes judged before them had crossed the line), spread
        evenly until they were read, and never faster than the line carries them.  On time (a virtual
        clock), that is when the line brings them.  ``(start, size, byte spacing)``."""
        start = max(state.judged_until, now - window)
        span = max(size * bt, now - start)
        state.judged_until = start + span
        return start, size, span / max(size, 1)

    def _pace(self, host: Any, state: _S100Host, now: float) -> None:
        """Read no further ahead of the serial line than :data:`LINE_AHEAD_S`: a pty takes a flood at
        once, the real line ~1 KB/s at 9600 baud, and every byte read early is a timer (0.37 MB kept per
        MB flooded before).  Reading resumes while the line is still busy, so the bytes read later are
        timed exactly as if they had been read at once; meanwhile the writer waits, as on a real port."""
        ahead = LINE_AHEAD_S * self.speed
        if state.line_in.free_at - now > ahead and state.resume_timer is None:
            host.pause()
            state.resume_timer = self.scheduler.at(state.line_in.free_at - ahead, self._resume, host, state)

    def _resume(self, host: Any, state: _S100Host) -> None:
        state.resume_timer = None
        host.resume()

    def _event(self, state: _S100Host, event: object) -> None:
        if isinstance(event, Decoded):
            self._send_other(state)  # what came before the frame goes first
            packet = self.port.packet
            real = event.real if not isinstance(packet, Raw) else event.payload
            # S100 frames carry no address of their own (a DataLinkFrame's header does): broadcast
            self.port.send(AppFrame(real, event.payload, packet, 0, self.port.address, event.dst,
                                    self.scheduler.now()))
            state.after_frame = True
            return
        after_frame, state.after_frame = state.after_frame, False
        if isinstance(event, Skipped):
            if event.reason == TERMINATOR and not state.other and after_frame:
                state.after_frame = True  # (its CR and LF may come in two reads)
                return  # the CR LF after a frame (not a CR or LF of a long frame's payload, sent in pieces)
            state.other += event.data
            if state.other.endswith(CRLF):
                self._send_other(state)
            elif state.buffer is not None and len(state.other) >= self.piece:
                self._piece(state, b"")
        elif isinstance(event, Notice):
            state.other += event.data  # as it came: a notice cut short by a frame has no CR LF of its own
            self._send_other(state)

    def _piece(self, state: _S100Host, data: bytes) -> None:
        """45 bytes without flow control: what is pending goes as packets of 45 bytes (the rest waits)."""
        state.after_frame = False
        state.other += data
        piece = self.piece
        while len(state.other) >= piece:
            self._send_raw(bytes(state.other[:piece]))
            del state.other[:piece]

    def _idle(self, state: _S100Host) -> None:
        """Nothing came for :data:`IDLE_S`: a frame still waiting for its CR LF goes (the modem's
        timeout), and what the hunter holds will not become a frame: send it as it is."""
        state.idle_timer = None
        if state.waiting is not None:
            self._event(state, state.waiting[0])
            state.waiting = None
        state.other += state.hunter.flush()
        self._send_other(state)

    def _send_other(self, state: _S100Host) -> None:
        data = bytes(state.other)
        state.other.clear()
        if data:
            self._send_raw(data)

    def _send_raw(self, data: bytes) -> None:
        """Bytes that are no frame, on air as they are (CR LF included): the far S100 writes them unchanged."""
        frame = AppFrame(data, data, Raw(), 0, self.port.address, BROADCAST, self.scheduler.now())
        frame.meta = {"s100": "raw"}
        self.port.send(frame)

    # -- channel → host ---------------------------------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        packet = self.port.packet
        wire = wire_class(packet)
        if (frame.meta or {}).get("s100") == "raw":
            data = frame.payload  # another S100's bytes, as they were (with their CR LF, if they had one)
        elif isinstance(packet, Raw):
            data = wire.encode(frame.payload) + CRLF
        elif frame.packet.name == packet.name:
            data = frame.real + CRLF
        else:
            data = packet.encode(frame.payload, src=frame.src, dst=frame.dst) + CRLF
        for host, state in list(self.states.items()):
            done = state.line_out.send(t, len(data))
            self.scheduler.at(done, host.write, data)  # the host has the whole line when its last byte is in
        return TAKEN

    def state(self, ready: bool) -> None:
        pass

    def close(self) -> None:
        for state in self.states.values():
            self.scheduler.cancel(state.idle_timer)
            self.scheduler.cancel(state.resume_timer)
        self.scheduler.unwatch_inputs(self.watch)
        super().close()


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
