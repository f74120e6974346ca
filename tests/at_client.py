"""An AT client for the emulator tests, written apart from hilgate's codec (so a bug there cannot hide
itself): its own line splitting, RECVIM/RECV framing by the length field, and the parsers of LSTS
DUNE's ``Transports.Evologics`` task re-expressed as regular expressions (``sscanf`` formats of
``Driver.hpp``, read from DUNE's source, not copied).

Like DUNE's ``BasicModem``, a line that starts with one of DUNE's asynchronous prefixes is a
notification; any other line answers the command in flight.  The client is stricter than DUNE where
DUNE would be confused later: a blank line, or a second answer to one command, is an error here
(DUNE's reader keeps the CR LF of a blank line in front of the next line, and an extra answer is read
as the answer to the next command).
"""

from __future__ import annotations

import re
import socket
import time

# DUNE's c_async_msgs (Driver.hpp): lines starting so are notifications.
DUNE_ASYNC = ("DELIVERED", "DELIVEREDIM", "FAILED", "FAILEDIM", "CANCELEDIM", "RECV", "RECVIMS", "RECVIM",
              "USBLLONG", "USBLANGLES", "USBLPHYD", "USBLPHYP", "BITRATE", "SRCLEVEL", "PHYON", "PHYOFF",
              "RECVSTART", "RECVFAILED", "RECVEND", "SENDSTART", "SENDEND", "SENDPBM", "RECVPBM", "RECVSRV",
              "STATUS")

# sscanf formats of DUNE's Driver.hpp, as regular expressions (%u: digits; %f: a float; %[^,]: no comma)
U = r"(\d+)"
F = r"([-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)"
DUNE_RECVIM = re.compile(rf"RECVIM,{U},{U},{U},([^,]+),{U},{F},{U},{F},".encode())
DUNE_RECV = re.compile(rf"RECV,{U},{U},{U},{U},{F},{U},{U},{F},".encode())
DUNE_I1 = re.compile(r"phy:[^0]+([^,]+),\s*mac:[^v]+v(\S+)")  # "phy:%*[^0]%[^,], mac:%*[^v]v%s"
DUNE_DELIVERED = re.compile(r"DELIVERED(?:IM)?,(\d+)")


def unsigned(text: str) -> int:
    """DUNE's castLexical into an unsigned: the whole text is a number that fits 32 bits."""
    assert re.fullmatch(r"\d+", text), f"not an unsigned integer: {text!r}"
    value = int(text)
    assert value < 2 ** 32, text
    return value


def multipath(text: str) -> list[int]:
    """DUNE's getMultipathStructure: 16 unsigned integers read with ``>>`` from one line."""
    words = text.split()
    assert len(words) >= 16, f"?P gives {len(words)} numbers, DUNE reads 16: {text!r}"
    return [unsigned(word) for word in words[:16]]


class Message:
    """A notification: its text up to the payload, and the payload of RECVIM/RECV."""

    def __init__(self, line: bytes, payload: bytes | None = None, t: float = 0.0):
        self.line = line
        self.payload = payload
        self.t = t  # when the client read it (wall clock; used only for ordering)
        self.text = line.decode("latin-1")
        self.name = self.text.split(",", 1)[0]

    def __repr__(self) -> str:
        return f"Message({self.line!r}, {self.payload!r})"


class AtClient:
    """One TCP connection to an emulated modem, speaking as DUNE does (``\\n`` after commands)."""

    def __init__(self, port: int, timeout: float = 15.0, eol: bytes = b"\n"):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        self.timeout = timeout
        self.eol = eol
        self.buffer = b""
        self.replies: list[str] = []
        self.messages: list[Message] = []
        self.blank_lines = 0

    def close(self) -> None:
        self.sock.close()

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def command(self, text: str | bytes) -> str:
        """Send ``AT<text>`` and return its one answer line."""
        body = text.encode("latin-1") if isinstance(text, str) else text
        assert not self.replies, f"answers nobody asked for: {self.replies}"
        self.send(b"AT" + body + self.eol)
        return self.reply()

    def reply(self) -> str:
        self.wait(lambda: bool(self.replies), "an answer")
        return self.replies.pop(0)

    def wait_message(self, name: str, timeout: float | None = None) -> Message:
        """The first notification called ``name`` not taken yet (others stay for later)."""
        found: list[Message] = []

        def check() -> bool:
            for message in self.messages:
                if message.name == name:
                    found.append(message)
                    self.messages.remove(message)
                    return True
            return False

        self.wait(check, name, timeout)
        return found[0]

    def wait(self, done, what: str, timeout: float | None = None) -> None:
        deadline = time.monotonic() + (timeout or self.timeout)
        while not done():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"no {what} within the timeout; have {self.replies} {self.messages}")
            self.sock.settimeout(remaining)
            try:
                data = self.sock.recv(65536)
            except socket.timeout:
                continue
            if not data:
                raise EOFError(f"connection closed while waiting for {what}")
            self.feed(data)

    def closed_by_peer(self, timeout: float = 10.0) -> bool:
        self.sock.settimeout(timeout)
        try:
            while True:
                data = self.sock.recv(65536)
                if not data:
                    return True
                self.feed(data)
        except (socket.timeout, ConnectionResetError):
            return False

    def feed(self, data: bytes) -> None:
        self.buffer += data
        while True:
            framed = self._framed()
            if framed is None:
                return
            if framed is False:
                end = self.buffer.find(b"\r\n")
                if end < 0:
                    return
                line, self.buffer = self.buffer[:end], self.buffer[end + 2:]
                self._line(line)

    def _framed(self):
        """A RECVIM/RECV at the head of the buffer, taken by its length field (None: wait for more)."""
        match = re.match(rb"(RECVIM|RECVPBM|RECV),(\d+),", self.buffer)
        if match is None:
            if re.fullmatch(rb"R(E(C(V(I(M)?|P(B(M)?)?)?)?)?)?", self.buffer[:7]) and b"\r\n" not in self.buffer:
                return None
            return False
        commas = {"RECVIM": 9, "RECVPBM": 8, "RECV": 9}[match.group(1).decode()]
        at = -1
        for _ in range(commas):
            at = self.buffer.find(b",", at + 1)
            if at < 0:
                return None
        length = int(match.group(2))
        end = at + 1 + length
        if len(self.buffer) < end + 2:
            return None
        assert self.buffer[end:end + 2] == b"\r\n", f"RECV not followed by CR LF: {self.buffer[:end + 2]!r}"
        self.messages.append(Message(self.buffer[:at + 1], self.buffer[at + 1:end], time.monotonic()))
        self.buffer = self.buffer[end + 2:]
        return True

    def _line(self, line: bytes) -> None:
        text = line.decode("latin-1")
        if text == "":
            self.blank_lines += 1
            return
        if text.startswith(DUNE_ASYNC):
            self.messages.append(Message(line, None, time.monotonic()))
        else:
            self.replies.append(text)
