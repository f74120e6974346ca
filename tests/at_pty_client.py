"""An AT client of its own for tests of the emulated EvoLogics modem: its own line splitting and its own
RECV* framing by the length field (never hilgate's codec), on a real pty opened with pyserial."""

from __future__ import annotations

import re
import time

import serial

RECV = re.compile(rb"(RECVIM|RECVIMS|RECVPBM|RECV),(?:p\d+,)?(\d+),")
COMMAS_BEFORE_DATA = {b"RECVIM": 9, b"RECVIMS": 9, b"RECVPBM": 8, b"RECV": 9}


class AtClient:
    def __init__(self, path: str):
        self.port = serial.Serial(str(path), 19200, timeout=0.05)
        self.buffer = b""
        self.lines: list[tuple[float, bytes, bytes | None]] = []  # (monotonic time, text, payload or None)

    def send(self, command: bytes) -> None:
        self.port.write(command + b"\r")

    def _pump(self) -> None:
        self.buffer += self.port.read(4096)
        while True:
            match = RECV.match(self.buffer)
            if match:
                commas = COMMAS_BEFORE_DATA[match.group(1)] + (1 if b",p" in self.buffer[:match.end()] else 0)
                cut = -1
                for _ in range(commas):
                    cut = self.buffer.find(b",", cut + 1)
                    if cut < 0:
                        return
                length = int(match.group(2))
                end = cut + 1 + length
                if len(self.buffer) < end + 2:
                    return
                assert self.buffer[end:end + 2] == b"\r\n", self.buffer
                self.lines.append((time.monotonic(), self.buffer[:cut], self.buffer[cut + 1:end]))
                self.buffer = self.buffer[end + 2:]
                continue
            newline = self.buffer.find(b"\r\n")
            if newline < 0:
                return
            line = self.buffer[:newline]
            self.buffer = self.buffer[newline + 2:]
            if line:
                self.lines.append((time.monotonic(), line, None))

    def expect(self, prefix: bytes, timeout: float = 20.0) -> tuple[bytes, bytes | None]:
        """The first line (taken out of the list) that starts with ``prefix``."""
        deadline = time.monotonic() + timeout
        while True:
            for i, (_, text, payload) in enumerate(self.lines):
                if text.startswith(prefix):
                    del self.lines[i]
                    return text, payload
            if time.monotonic() > deadline:
                raise AssertionError(f"no {prefix!r} within {timeout} s; lines: {self.lines}")
            self._pump()

    def ask(self, command: bytes, timeout: float = 10.0) -> bytes:
        """Send a command and return the next line that is no notification."""
        self.send(command)
        deadline = time.monotonic() + timeout
        while True:
            for i, (_, text, payload) in enumerate(self.lines):
                if payload is None and not text.startswith((b"RECV", b"DELIVERED", b"FAILED", b"USBL", b"SEND")):
                    del self.lines[i]
                    return text
            if time.monotonic() > deadline:
                raise AssertionError(f"no answer to {command!r}; lines: {self.lines}")
            self._pump()

    def settle(self, seconds: float) -> list[bytes]:
        """Read for ``seconds`` and return every line text seen (and kept) so far."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self._pump()
        return [text for _, text, _ in self.lines]

    def close(self) -> None:
        self.port.close()
