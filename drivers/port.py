"""A modem's byte stream in the real-time loop, that survives the USB adapter being pulled.

The device is opened with pyserial (a path such as ``/dev/ttyUSB0``, or a URL of one of pyserial's
handlers, such as ``socket://192.168.0.212:9200`` for an EvoLogics modem over TCP).  A device node
or a TCP socket is read and written through its file descriptor in the scheduler's epoll loop, never
blocking it.  The other handlers have no descriptor worth polling (``loop://``, ``rfc2217://``, whose
bytes pass through a Telnet filter, ``spy://``, which logs what pyserial reads and writes): they are
read and written through pyserial by two small threads, as pyserial's own miniterm does, which hand
bytes to the loop with the scheduler's thread-safe ``post()``.

When the device vanishes (EIO, EOF, a write error) the port closes, tells its owner it is down, and
tries to reopen with backoff (0.5 s doubling to ``max_backoff_s``) at the same path, like gpsd does,
until it is back.  An outage is logged once at WARNING (its reason is kept for ``hilgate status``),
not once per attempt.  Reconnection is a property of the port, not of each driver.

:func:`port_problem` tells, when a scene is loaded, whether a port spec is one hilgate can open at all,
so a misspelt URL is a scene error rather than a link retrying forever.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import re
import threading
from typing import Any, Callable
from urllib.parse import parse_qs, urlsplit

import serial
import serial.serialposix
from serial.urlhandler import protocol_socket

from hilgate.core.streams import Outbox

log = logging.getLogger(__name__)

READ_WAIT_S = 0.1  # how long a reader thread blocks in pyserial before it looks whether to stop

# Classes whose descriptor carries exactly the device's bytes: polled in the loop.  Subclasses that
# override read/write (spy://) are not in this set on purpose.
POLLABLE = (serial.serialposix.Serial, serial.serialposix.PosixPollSerial, serial.serialposix.VTIMESerial,
            protocol_socket.Serial)

# -- what a port spec may be ----------------------------------------------------------------------

LOGGING_LEVELS = ("debug", "info", "warning", "error")


def _flag(values: list[str]) -> str | None:
    return None if values == [""] else "takes no value"


def _level(values: list[str]) -> str | None:
    return None if values[-1] in LOGGING_LEVELS else f"must be one of {', '.join(LOGGING_LEVELS)}"


def _seconds(values: list[str]) -> str | None:
    try:
        return None if float(values[-1]) > 0 else "must be positive"
    except ValueError:
        return "must be a number of seconds"


def _any(values: list[str]) -> str | None:
    return None if values[-1] else "needs a value"


def _options(scheme: str, query: str, allowed: dict[str, Callable[[list[str]], str | None]]) -> str | None:
    for option, values in parse_qs(query, keep_blank_values=True).items():
        check = allowed.get(option)
        if check is None:
            known = ", ".join(allowed) or "none"
            return f"unknown {scheme}:// option '{option}' (known: {known})"
        problem = check(values)
        if problem:
            return f"{scheme}:// option '{option}' {problem}"
    return None


def _host_port(scheme: str, url: str, allowed: dict) -> str | None:
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = -1
    if not parts.hostname or port is None or not 0 < port < 65536 or parts.path not in ("", "/"):
        return f"expected {scheme}://HOST:PORT (PORT 1-65535), not '{url}'"
    return _options(scheme, parts.query, allowed)


def _check_socket(url: str) -> str | None:
    return _host_port("socket", url, {"logging": _level})


def _check_rfc2217(url: str) -> str | None:
    return _host_port("rfc2217", url, {"logging": _level, "ign_set_control": _flag, "poll_modem": _flag,
                                       "timeout": _seconds})


def _check_loop(url: str) -> str | None:
    parts = urlsplit(url)
    if parts.netloc or parts.path:
        return f"loop:// takes only options (loop://?logging=debug), not '{url}'"
    return _options("loop", parts.query, {"logging": _level})


def _check_spy(url: str) -> str | None:
    parts = urlsplit(url)
    inner = parts.netloc + parts.path
    if not inner:
        return "spy:// needs a device path after it (spy:///dev/ttyUSB0)"
    if "://" in url[len("spy://"):].split("?", 1)[0]:
        return "spy:// wraps a device path (spy:///dev/ttyUSB0), not another URL"
    def broken(values: list[str]) -> str:
        return "writes bytes to a text stream and fails at the first byte (pyserial 3.5); leave it out"

    return _options("spy", parts.query, {"file": _any, "color": _flag, "raw": broken, "all": _flag})


def _check_alt(url: str) -> str | None:
    parts = urlsplit(url)
    if not parts.netloc + parts.path:
        return "alt:// needs a device path after it (alt:///dev/ttyUSB0?class=PosixPollSerial)"
    # by name: pyserial's classes differ by platform
    classes = [name for name in ("Serial", "PosixPollSerial", "VTIMESerial") if hasattr(serial, name)]

    def known_class(values: list[str]) -> str | None:
        return None if values[-1] in classes else f"must be one of {', '.join(classes)}"

    return _options("alt", parts.query, {"class": known_class})


def _check_hwgrep(url: str) -> str | None:
    regexp, *args = url[len("hwgrep://"):].split("&")
    try:
        re.compile(regexp)
    except re.error as exc:
        return f"hwgrep:// regular expression: {exc}"
    for arg in args:
        option, _, value = arg.partition("=")
        if option == "n" and not (value.isdigit() and int(value) >= 2):
            return "hwgrep:// option 'n' must be an integer >= 2 (pyserial counts from 1 and refuses n=1)"
        if option not in ("n", "skip_busy"):
            return f"unknown hwgrep:// option '{option}' (known: n, skip_busy)"
    return None


def _check_cp2110(url: str) -> str | None:
    if importlib.util.find_spec("hid") is None:
        return "cp2110:// needs the hidapi package (pip install hidapi), which is not installed"
    return None


SCHEMES: dict[str, Callable[[str], str | None]] = {
    "socket": _check_socket, "loop": _check_loop, "rfc2217": _check_rfc2217, "spy": _check_spy,
    "alt": _check_alt, "hwgrep": _check_hwgrep, "cp2110": _check_cp2110,
}


def port_problem(url: str) -> str | None:
    """None if hilgate can open this port spec (now or once the device is plugged in), else why not
    (one line).  It checks the spec only, without opening anything or writing a spy log: a device
    that is missing is an outage the port rides out, not a configuration error."""
    if not isinstance(url, str) or not url.strip():
        return "empty port (give a device such as /dev/ttyUSB0 or a URL such as socket://HOST:PORT)"
    if "\0" in url:
        return "the port contains a NUL character"
    if "://" not in url:
        return None
    scheme = url.partition("://")[0]
    check = SCHEMES.get(scheme.lower())
    if check is None:
        return (f"unknown URL scheme '{scheme}://' (hilgate opens a device path or one of pyserial's "
                + ", ".join(s + "://" for s in SCHEMES) + ")")
    return check(url)


def _post(scheduler: Any, fn: Callable[..., Any], *args: Any) -> None:
    """Hand ``fn(*args)`` to the loop from a thread; nothing if the loop is gone (the daemon stopped)."""
    try:
        scheduler.post(fn, *args)
    except (OSError, ValueError):
        pass


def _close_quietly(device: Any) -> None:
    if device is not None:
        try:
            device.close()
        except Exception:
            pass


def _describe(exc: BaseException | None) -> str:
    """One line for a failure, without pyserial's "could not open port URL:" (the caller names it)."""
    if exc is None:
        return "end of file"
    text = re.sub(r"^(\[Errno -?\d+\] )?could not open port \S+: ", "", str(exc), flags=re.IGNORECASE)
    return text or type(exc).__name__


# -- devices without a descriptor to poll ----------------------------------------------------------


class _Pump:
    """Reads and writes a pyserial device through pyserial in two threads (as miniterm does): the
    reader blocks at most ``READ_WAIT_S`` in ``read()`` and posts what it got to the loop; the writer
    takes what the loop queued (at most ``max_buffer`` bytes).  A failure in either is posted once; the
    reader closes the device when the pump stops, so the loop never waits for pyserial."""

    def __init__(self, device: Any, name: str, scheduler: Any, on_data: Callable[["_Pump", bytes], Any],
                 on_error: Callable[["_Pump", BaseException], Any], max_buffer: int):
        self.device = device
        self.scheduler = scheduler
        self.on_data = on_data
        self.on_error = on_error
        self.max_buffer = max_buffer
        self.pending = bytearray()
        self.cond = threading.Condition()
        self.stopped = False
        self.writer = threading.Thread(target=self._write, name=f"port-{name}-w", daemon=True)
        self.reader = threading.Thread(target=self._read, name=f"port-{name}-r", daemon=True)
        self.writer.start()
        self.reader.start()

    def write(self, data: bytes) -> bool:
        with self.cond:
            if self.stopped or len(self.pending) + len(data) > self.max_buffer:
                return False
            self.pending += data
            self.cond.notify()
        return True

    def stop(self) -> None:
        with self.cond:
            self.stopped = True
            self.pending.clear()
            self.cond.notify_all()

    def _fail(self, exc: BaseException) -> None:
        with self.cond:
            if self.stopped:
                return
        _post(self.scheduler, self.on_error, self, exc)

    def _read(self) -> None:
        device = self.device
        try:
            while not self.stopped:
                data = device.read(min(max(device.in_waiting, 1), 4096))
                if data and not self.stopped:
                    _post(self.scheduler, self.on_data, self, data)
        except Exception as exc:  # any handler's failure is the device's loss, never the loop's
            self._fail(exc)
        finally:
            self.stop()
            self.writer.join()
            _close_quietly(device)

    def _write(self) -> None:
        while True:
            with self.cond:
                while not self.pending and not self.stopped:
                    self.cond.wait()
                if self.stopped:
                    return
                chunk = bytes(self.pending)
                self.pending.clear()
            try:
                self.device.write(chunk)
            except Exception as exc:
                self._fail(exc)
                return


# -- the port -------------------------------------------------------------------------------------


class Port:
    """``on_state(up, reason)``: up with reason None when the device opens, down with why (one line)
    when it is lost or cannot be opened, again whenever that reason changes."""

    def __init__(self, url: str, scheduler: Any, on_data: Callable[[bytes], Any],
                 on_state: Callable[[bool, str | None], Any], baud: int = 19200, rtscts: bool = False,
                 name: str = "", max_backoff_s: float = 8.0, max_buffer: int = 1 << 16):
        self.url = url
        self.scheduler = scheduler
        self.on_data = on_data
        self.on_state = on_state
        self.baud = baud
        self.rtscts = rtscts
        self.name = name or url
        self.max_backoff_s = max_backoff_s
        self.max_buffer = max_buffer
        self.device: Any = None
        self.fd: int | None = None
        self.pump: _Pump | None = None
        self.up = False
        self.closed = False
        self.backoff = 0.5
        self.reopen_timer = None
        self.opening = False
        self.attempts = 0
        self.outbox: Outbox | None = None
        self.reason: str | None = None  # why the port is down (None while up, or before the first try)

    def open(self) -> None:
        """Try now, in a thread (a TCP connect or an RFC 2217 negotiation may take seconds, and the
        loop must not wait for it); on failure, retry later.  Never raises."""
        self.reopen_timer = None
        if self.closed or self.opening:
            return
        self.attempts += 1
        self.opening = True
        threading.Thread(target=self._open_in_thread, name=f"port-{self.name}-open", daemon=True).start()

    def _open_in_thread(self) -> None:
        try:
            device, exc = self._open_device(), None
        except Exception as error:  # whatever a handler raises, the device is just not there yet
            device, exc = None, error
        _post(self.scheduler, self._opened, device, exc)

    def _opened(self, device: Any, exc: BaseException | None) -> None:
        self.opening = False
        if self.closed:
            _close_quietly(device)
            return
        if exc is not None:
            self._cannot_open(exc)
            return
        self.device = device
        if type(device) in POLLABLE:
            fd = self.fd = device.fileno()
            os.set_blocking(fd, False)
            self.outbox = Outbox(self.scheduler, fd, lambda data: os.write(fd, data), self._lost, self.max_buffer)
            self.scheduler.add_reader(fd, self._readable)
        else:
            self.pump = _Pump(device, self.name, self.scheduler, self._pumped, self._pump_failed, self.max_buffer)
        log.info("%s: %s open%s", self.name, self.url, " again" if self.reason is not None else "")
        self.up = True
        self.backoff = 0.5
        self.reason = None
        self.on_state(True, None)

    def _open_device(self) -> Any:
        device = serial.serial_for_url(self.url, baudrate=self.baud, rtscts=self.rtscts, do_not_open=True)
        polled = type(device) in POLLABLE
        device.timeout = 0 if polled else READ_WAIT_S
        device.write_timeout = 0 if polled else None
        device.open()
        return device

    def _cannot_open(self, exc: BaseException) -> None:
        reason = f"cannot open {self.url}: {_describe(exc)}"
        if self.reason is None:  # a new outage (at start): the one warning
            log.warning("%s: %s; retrying with backoff up to %g s", self.name, reason, self.max_backoff_s)
        elif reason != self.reason:
            log.info("%s: %s; still retrying", self.name, reason)
        else:
            log.debug("%s: %s; retrying", self.name, reason)
        changed = reason != self.reason
        self.reason = reason
        if changed:
            self.on_state(False, reason)
        self._retry()

    def _retry(self) -> None:
        delay = self.backoff
        self.backoff = min(self.backoff * 2, self.max_backoff_s)
        self.reopen_timer = self.scheduler.after_wall(delay, self.open)

    def _readable(self) -> None:
        try:
            data = os.read(self.fd, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._lost(exc)
            return
        if not data:
            self._lost(None)
            return
        self.on_data(data)

    def _pumped(self, pump: _Pump, data: bytes) -> None:
        if pump is self.pump:  # not bytes a stopped pump read before it noticed
            self.on_data(data)

    def _pump_failed(self, pump: _Pump, exc: BaseException) -> None:
        if pump is self.pump:
            self._lost(exc)

    def write(self, data: bytes) -> bool:
        """Queue bytes for the device; False if it is down or its backlog is full (the caller keeps or
        drops what it sends)."""
        if not self.up:
            return False
        if self.pump is not None:
            return self.pump.write(data)
        return self.outbox.write(data)

    def _release(self) -> None:
        if self.pump is not None:
            self.pump.stop()  # its reader thread closes the device
        else:
            if self.fd is not None:
                self.outbox.clear()
                self.scheduler.remove_reader(self.fd)
            _close_quietly(self.device)
        self.device = self.fd = self.pump = None
        self.up = False

    def _lost(self, exc: BaseException | None) -> None:
        if not self.up:
            return
        self.reason = f"lost {self.url}: {_describe(exc)}"
        log.warning("%s: %s; reopening with backoff up to %g s", self.name, self.reason, self.max_backoff_s)
        self._release()
        self.on_state(False, self.reason)
        if not self.closed:
            self._retry()

    def close(self) -> None:
        self.closed = True
        if self.reopen_timer is not None:
            self.scheduler.cancel(self.reopen_timer)
        self._release()
