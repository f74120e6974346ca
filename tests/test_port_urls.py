"""Modem ports given as pyserial URLs, and ports that cannot be opened.

Every port here is real: pseudo-terminals from ``os.openpty``, pyserial's own URL handlers
(``loop://`` echoes what is written; ``rfc2217://`` talks to pyserial's RFC 2217 server side,
``PortManager``, in front of a ``loop://``; ``spy://`` logs what passes), TCP servers on loopback
ports picked by the kernel.  Nothing of pyserial is mocked.
"""

import logging
import os
import socket
import subprocess
import sys
import threading
import time
import tty

import pytest
import serial
import serial.rfc2217

from daemon_kit import unique
from hilgate.core.backend import AppFrame
from hilgate.client import Link
from hilgate.drivers.port import port_problem
from hilgate.drivers.s100 import S100Backend, S100Options
from hilgate.core.packets import packet_class
from hilgate.core.realtime import RealtimeScheduler

# -- what is refused when the scene is loaded --------------------------------------------------------


@pytest.mark.parametrize("spec", [
    "/dev/ttyUSB0", "relative/tty", "socket://192.168.0.212:9200", "socket://modem.local:9200?logging=debug",
    "loop://", "loop://?logging=info", "rfc2217://127.0.0.1:2217", "rfc2217://host:2217?ign_set_control&timeout=5",
    "spy:///dev/ttyUSB0", "spy:///dev/ttyUSB0?file=/tmp/spy.txt&color", "alt:///dev/ttyUSB0?class=PosixPollSerial",
    "hwgrep://0403:6001", "hwgrep://USB&skip_busy&n=2",
])
def test_port_specs_hilgate_can_open_pass(spec):
    assert port_problem(spec) is None


@pytest.mark.parametrize("spec,why", [
    ("", "empty port"),
    ("   ", "empty port"),
    ("ftp://modem/file", "unknown URL scheme 'ftp://'"),
    ("socket://modem", "expected socket://HOST:PORT"),
    ("socket://:9200", "expected socket://HOST:PORT"),
    ("socket://modem:99999", "expected socket://HOST:PORT"),
    ("socket://modem:9200?nodelay", "unknown socket:// option 'nodelay'"),
    ("socket://modem:9200?logging=loud", "option 'logging' must be one of"),
    ("rfc2217://modem", "expected rfc2217://HOST:PORT"),
    ("rfc2217://modem:2217?timeout=soon", "option 'timeout' must be a number"),
    ("loop://somewhere", "loop:// takes only options"),
    ("spy://", "needs a device path"),
    ("spy://loop://", "wraps a device path"),
    ("spy:///dev/ttyUSB0?colour", "unknown spy:// option 'colour'"),
    ("spy:///dev/ttyUSB0?raw", "option 'raw' writes bytes to a text stream"),
    ("alt:///dev/ttyUSB0?class=Nope", "option 'class' must be one of"),
    ("hwgrep://(", "regular expression"),
    ("hwgrep://USB&n=1", "option 'n'"),
    ("/dev/tty\0USB0", "NUL"),
])
def test_port_specs_hilgate_cannot_open_are_refused_with_a_reason(spec, why):
    problem = port_problem(spec)
    assert problem is not None and why in problem and "\n" not in problem


def test_cp2110_is_refused_when_hidapi_is_missing():
    import importlib.util

    problem = port_problem("cp2110://0001:0002:00")
    if importlib.util.find_spec("hid") is None:
        assert problem is not None and "hidapi" in problem
    else:
        assert problem is None


# -- real peers ---------------------------------------------------------------------------------------


class LoopbackServer:
    """A TCP server on a free loopback port; each connection it accepts is handed to :meth:`accepted`."""

    def __init__(self):
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                conn, _ = self.listener.accept()
            except OSError:  # closed: the test is over
                return
            self.accepted(conn)

    def accepted(self, conn) -> None:
        conn.close()

    def close(self):
        self.listener.close()


class EchoServer(LoopbackServer):
    """Sends back what it gets (a modem in loopback), to each client on a thread of its own."""

    def accepted(self, conn):
        threading.Thread(target=self._echo, args=(conn,), daemon=True).start()

    @staticmethod
    def _echo(conn):
        with conn:
            while data := conn.recv(4096):
                conn.sendall(data)


class Rfc2217Server(LoopbackServer):
    """pyserial's RFC 2217 server side (``PortManager``, as in its ``rfc2217_server.py`` example) in
    front of a ``loop://`` serial port: a networked serial port in loopback.  One client at a time;
    :meth:`drop` cuts the current one off (the network cable pulled)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.conn = None
        self.clients = 0
        super().__init__()

    def accepted(self, conn):
        with self.lock:
            self.conn = conn
            self.clients += 1
        self._client(conn)

    def _client(self, conn):
        device = serial.serial_for_url("loop://", timeout=0.05)
        manager = serial.rfc2217.PortManager(device, _Sender(conn, self.lock))
        done = threading.Event()
        threading.Thread(target=self._to_client, args=(device, manager, done), daemon=True).start()
        try:
            while data := conn.recv(1024):
                device.write(b"".join(manager.filter(data)))
        except OSError:
            pass
        finally:
            done.set()
            conn.close()

    @staticmethod
    def _to_client(device, manager, done):
        while not done.is_set():
            data = device.read(device.in_waiting or 1)
            if data:
                try:
                    manager.connection.write(b"".join(manager.escape(data)))
                except OSError:
                    return

    def drop(self):
        with self.lock:
            self.conn.shutdown(socket.SHUT_RDWR)

    def close(self):
        super().close()
        if self.conn is not None:
            self.conn.close()


class _Sender:
    """What PortManager writes to: the client's socket."""

    def __init__(self, conn, lock):
        self.conn = conn
        self.lock = lock

    def write(self, data):
        with self.lock:
            self.conn.sendall(data)


def one_link_scene(link: str, port: str, packet: str = "vl2b") -> str:
    return f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  v0: {{pose: {{static: [0, 0, 0]}}}}
links:
  {link}: {{vehicle: v0, backend: s100, port: "{port}", address: 1, packet: {packet}}}
"""


def wait_state(daemon, link, wanted, timeout=60.0):
    deadline = time.monotonic() + timeout
    while (state := daemon.link_status(link)["state"]) != wanted:
        assert time.monotonic() < deadline, f"{link} is {state}, never {wanted}:\n{daemon.output()}"
        time.sleep(0.05)


def echoes(daemon, link, payloads):
    """What comes back to the application that sent ``payloads`` on a link whose modem loops back."""
    with Link.open(link, runtime_dir=daemon.runtime) as app:
        got = []
        for payload in payloads:
            app.send(payload, dst=1)
            message = app.recv(timeout=10)
            got.append(None if message is None else message.data)
    return got


PAYLOADS = [b"ping %d\r\n\0+++AT" % i for i in range(3)]


def a_link_that_echoes(daemon_of, url: str) -> tuple:
    """A daemon with one driver link on ``url``, whose far end echoes: the link comes up and every payload
    comes back as it was sent.  Returns the daemon and the link."""
    link = unique("u")
    daemon = daemon_of(one_link_scene(link, url), [link])
    wait_state(daemon, link, "up")
    assert echoes(daemon, link, PAYLOADS) == PAYLOADS
    return daemon, link


def test_a_driver_link_on_loop_url_comes_up_and_echoes(daemon_of):
    daemon, _ = a_link_that_echoes(daemon_of, "loop://")
    assert "fileno" not in daemon.output()


def test_a_driver_link_on_rfc2217_comes_up_echoes_and_comes_back_after_the_network_drops(daemon_of):
    server = Rfc2217Server()
    try:
        daemon, link = a_link_that_echoes(daemon_of, f"rfc2217://127.0.0.1:{server.port}")
        server.drop()
        wait_state(daemon, link, "down")
        wait_state(daemon, link, "up")
        assert server.clients == 2
        assert echoes(daemon, link, PAYLOADS) == PAYLOADS
    finally:
        server.close()


def test_a_driver_link_on_socket_url_comes_up_and_echoes(daemon_of):
    server = EchoServer()
    try:
        a_link_that_echoes(daemon_of, f"socket://127.0.0.1:{server.port}")
    finally:
        server.close()


def raw_pty():
    master, slave = os.openpty()
    tty.setraw(slave)
    return master, slave


def read_until(fd, wanted: bytes, timeout=10.0, meanwhile=lambda: time.sleep(0.02)) -> bytes:
    """Read the pty's master until ``wanted`` came; ``meanwhile()`` lets the sender get on."""
    got = b""
    deadline = time.monotonic() + timeout
    os.set_blocking(fd, False)
    while wanted not in got:
        assert time.monotonic() < deadline, f"never got {wanted!r}; got {got!r}"
        try:
            got += os.read(fd, 4096)
        except BlockingIOError:
            meanwhile()
    return got


def test_a_driver_link_on_spy_url_reads_and_writes_through_pyserial_so_the_spy_sees_it(tmp_path, daemon_of):
    link = unique("sp")
    master, slave = raw_pty()
    spy_log = tmp_path / "spy.txt"
    vl2b = packet_class("vl2b")
    daemon = daemon_of(one_link_scene(link, f"spy://{os.ttyname(slave)}?file={spy_log}"), [link])
    try:
        wait_state(daemon, link, "up")
        with Link.open(link, runtime_dir=daemon.runtime) as app:
            app.send(b"to the modem", dst=1)
            read_until(master, vl2b.encode(b"to the modem") + b"\r\n")
            os.write(master, vl2b.encode(b"from the modem") + b"\r\n")
            message = app.recv(timeout=10)
            assert message is not None and message.data == b"from the modem"
        lines = spy_log.read_text().splitlines()  # pyserial's hex dump of what it wrote and read
        assert any(" TX " in line and "to the modem" in line for line in lines), lines
        assert any(" RX " in line and "from the modem" in line for line in lines), lines
    finally:
        os.close(master)
        os.close(slave)


def test_a_port_that_cannot_be_opened_shows_down_and_is_warned_once(daemon_of):
    link = unique("dn")
    refusing = socket.socket()  # bound and never listening: connections are refused, and the port is ours
    refusing.bind(("127.0.0.1", 0))
    daemon = daemon_of(one_link_scene(link, f"socket://127.0.0.1:{refusing.getsockname()[1]}"), [link])
    try:
        wait_state(daemon, link, "down")

        def lines(level):  # the daemon logs "… LEVEL logger: message", whatever comes before LEVEL
            return [line for line in daemon.output().splitlines() if f"{level} hilgate.drivers.port:" in line]

        time.sleep(2.5)  # retries after 0.5 and 1.5 s (counted exactly in the in-process test below)
        assert daemon.link_status(link)["state"] == "down"
        warnings = [line for line in lines("WARNING") if "cannot open" in line]
        assert len(warnings) == 1 and "Connection refused" in warnings[0], daemon.output()
        assert not any("cannot open" in line for line in lines("INFO")), daemon.output()
        assert "Connection refused" in daemon.link_status(link)["reason"]
        table = subprocess.run([sys.executable, "-m", "hilgate", "status", "--runtime-dir", daemon.runtime],
                               capture_output=True, text=True, timeout=60)
        row = next(line for line in table.stdout.splitlines() if line.startswith(link))
        assert " down " in row and "Connection refused" in row  # hilgate status says why
    finally:
        refusing.close()


# -- the backend's state and reason, in process ---------------------------------------------------


def run_until(scheduler, predicate, timeout=20.0):
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        scheduler.run(until=scheduler.model_time() + 0.02)


def test_the_backend_says_why_it_is_down_and_forgets_it_when_up(tmp_path, caplog):
    caplog.set_level(logging.DEBUG, logger="hilgate.drivers.port")
    path = str(tmp_path / "ttyUSB7")
    scheduler = RealtimeScheduler()
    trace = []
    backend = S100Backend("s", 1, packet_class("vl2b"), S100Options(port=path), scheduler, trace.append)
    received = []
    backend.on_receive = received.append
    pty = None
    try:
        run_until(scheduler, lambda: backend.port.attempts >= 3)
        status = backend.status()
        assert backend.state == "down" and status["reason"].startswith(f"cannot open {path}: [Errno 2] No such file")
        warned = [r for r in caplog.records if r.levelno >= logging.WARNING]
        assert len(warned) == 1 and "cannot open" in warned[0].getMessage()
        assert [e["state"] for e in trace if e["ev"] == "link"] == ["down"]
        assert "No such file" in next(e for e in trace if e["ev"] == "link")["reason"]

        pty = raw_pty()  # plugged in
        os.symlink(os.ttyname(pty[1]), path)
        run_until(scheduler, lambda: backend.state == "up")
        assert backend.status()["reason"] is None
        vl2b = packet_class("vl2b")
        os.write(pty[0], vl2b.encode(b"hello") + b"\r\n")
        run_until(scheduler, lambda: received)
        assert received[0].payload == b"hello"
        backend.send(AppFrame(vl2b.encode(b"out"), b"out", vl2b, 1, 1, 2))
        read_until(pty[0], vl2b.encode(b"out") + b"\r\n",
                   meanwhile=lambda: scheduler.run(until=scheduler.model_time() + 0.02))

        os.unlink(path)  # pulled out
        os.close(pty[0])
        os.close(pty[1])
        pty = None
        run_until(scheduler, lambda: backend.state == "down")
        assert backend.status()["reason"].startswith("lost")
        run_until(scheduler, lambda: "cannot open" in (backend.status()["reason"] or ""))
        attempts = backend.port.attempts
        run_until(scheduler, lambda: backend.port.attempts >= attempts + 2)
        warned = [r for r in caplog.records if r.levelno >= logging.WARNING]
        assert len(warned) == 2 and "lost" in warned[1].getMessage()  # one per outage
    finally:
        backend.close()
        scheduler.close()
        if pty is not None:
            os.close(pty[0])
            os.close(pty[1])
