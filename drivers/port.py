"""A modem's byte stream in the real-time loop, that survives the USB adapter being pulled.

The device is opened with pyserial (a path such as ``/dev/ttyUSB0``, or a URL such as
``socket://192.168.0.212:9200`` for an EvoLogics modem over TCP) and then read and written through
its file descriptor in the scheduler's epoll loop, never blocking it.  When the device vanishes
(EIO, EOF, a write error) the port closes, tells its owner it is down, and tries to reopen with
backoff (0.5 s doubling to ``max_backoff_s``) at the same path, like gpsd does, until it is back.
Reconnection is a property of the port, not of each driver.
"""

from __future__ import annotations

import logging
import os
import socket
from typing import Any, Callable

import serial

from hilgate.streams import Outbox

log = logging.getLogger(__name__)

# pyserial's URL handlers (serial.urlhandler.protocol_*) that hilgate opens; a path without "://" is a
# device node.  Anything else would pass validation and then retry forever, so it is refused at load.
SCHEMES = ("socket", "loop", "rfc2217", "spy", "alt", "hwgrep")


def port_problem(url: str) -> str | None:
    """None if hilgate can open this port spec (now or once the device is plugged in), else why not
    (one line).  Checks the spelling only: a missing device is an outage the port rides out, not a
    configuration error."""
    if not isinstance(url, str) or not url.strip():
        return "empty port (give a device such as /dev/ttyUSB0 or a URL such as socket://HOST:PORT)"
    if "\0" in url:
        return "the port contains a NUL character"
    if "://" not in url:
        return None
    scheme, _, rest = url.partition("://")
    if scheme.lower() not in SCHEMES:
        return (f"unknown URL scheme '{scheme}://' (hilgate opens a device path or "
                + ", ".join(s + "://" for s in SCHEMES) + ")")
    if not rest and scheme.lower() not in ("loop",):
        return f"'{scheme}://' needs what to open after it"
    return None


class Port:
    def __init__(self, url: str, scheduler: Any, on_data: Callable[[bytes], Any], on_state: Callable[[bool], Any],
                 baud: int = 19200, rtscts: bool = False, name: str = "", max_backoff_s: float = 8.0,
                 max_buffer: int = 1 << 16):
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
        self.up = False
        self.closed = False
        self.backoff = 0.5
        self.reopen_timer = None
        self.opens = 0
        self.losses = 0
        self.outbox: Outbox | None = None

    def open(self) -> None:
        """Try now; on failure, retry later (never raises)."""
        self.reopen_timer = None
        if self.closed:
            return
        try:
            device = serial.serial_for_url(self.url, baudrate=self.baud, rtscts=self.rtscts, timeout=0,
                                           write_timeout=0, do_not_open=False)
            fd = device.fileno()
            if not isinstance(device, serial.Serial) or self.url.startswith("socket://"):
                os.set_blocking(fd, False)
        except (serial.SerialException, OSError, ValueError) as exc:
            if self.backoff <= 0.5 or self.backoff >= self.max_backoff_s:
                log.info("%s: cannot open %s (%s); retrying", self.name, self.url, exc)
            self._retry()
            return
        self.device, self.fd = device, fd
        self.up = True
        self.opens += 1
        self.backoff = 0.5
        self.outbox = Outbox(self.scheduler, fd, lambda data: os.write(fd, data), self._lost, self.max_buffer)
        self.scheduler.add_reader(fd, self._readable)
        log.info("%s: %s open", self.name, self.url)
        self.on_state(True)

    def _retry(self) -> None:
        delay = self.backoff
        self.backoff = min(self.backoff * 2, self.max_backoff_s)
        self.reopen_timer = self.scheduler.at(self.scheduler.now() + delay * getattr(self.scheduler, "speed", 1.0),
                                              self.open)

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

    def write(self, data: bytes) -> bool:
        """Queue bytes for the device; False if it is down (the caller keeps or drops what it sends)."""
        if not self.up:
            return False
        return self.outbox.write(data)

    def _release(self) -> None:
        if self.fd is not None:
            self.outbox.clear()
            self.scheduler.remove_reader(self.fd)
        if self.device is not None:
            try:
                self.device.close()
            except (serial.SerialException, OSError, socket.error):
                pass
        self.device = self.fd = None
        self.up = False

    def _lost(self, exc: OSError | None) -> None:
        log.warning("%s: %s lost (%s); reopening with backoff", self.name, self.url, exc or "end of file")
        self.losses += 1
        self._release()
        self.on_state(False)
        if not self.closed:
            self._retry()

    def close(self) -> None:
        self.closed = True
        if self.reopen_timer is not None:
            self.scheduler.cancel(self.reopen_timer)
        self._release()
