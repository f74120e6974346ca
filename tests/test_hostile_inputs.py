"""The last tracebacks of issue 23 (item 7): each hostile input is a one-line error or bounded behaviour.

Emulator arguments (``AT!UT`` with 30 digits), a flow's frame size (a stated maximum), ``hilgate app``'s
parameters and Zenoh endpoints, an S100 emulator flooded through its pty (its reading is paced by its
serial line, so the writer waits and the daemon's memory stays put), and a cap on an emulated modem's
TCP clients.  Every daemon here runs for real, its emulated modems on real ptys and sockets.
"""

import os
import socket
import subprocess
import time
import tty

import pytest

from at_client import AtClient
from daemon_kit import Daemon, free_port, hilgate, unique
from doorkit import closed_by_peer, idle, listening_addresses
from hilgate.drivers.emulators import MAX_TCP_CLIENTS
from hilgate.scene import SceneError, load_scene_text
from hilgate.scene.flow_spec import MAX_FRAME_BYTES

TWO_VEHICLES = """\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{va: {{pose: {{static: [0, 0, 0]}}}}, vb: {{pose: {{static: [10, 0, 0]}}}}}}
links:
{links}
"""


def stopped(daemon: Daemon) -> str:
    """Stop the daemon and give its output (its log is closed with it)."""
    daemon.stop()
    output = daemon.output()
    daemon.close()
    return output


def one_error_line(result: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if "error" in line or line.startswith("hilgate:")]
    assert len(lines) == 1, result.stderr
    return lines[0]


# -- the EvoLogics emulator -----------------------------------------------------------------------------


def evologics_daemon(tmp_path, port: int) -> tuple[Daemon, str]:
    link = unique("ev")
    daemon = Daemon(tmp_path, TWO_VEHICLES.format(
        links=f"  {link}: {{vehicle: va, address: 4, emulate: {{protocol: evologics, tcp: {port}}}}}"), [link])
    daemon.wait_for("READY=1")
    return daemon, link


def test_evologics_emulator_answers_hostile_numbers_in_one_line(tmp_path):
    port = free_port()
    daemon, _ = evologics_daemon(tmp_path, port)
    try:
        modem = AtClient(port)
        huge = "9" * 30
        for command, answer in [
                ("!UT" + huge, "ERROR OUT OF RANGE"),        # an OverflowError in the loop before
                ("!UT" + "9" * 400, "ERROR OUT OF RANGE"),
                ("!UT" + "9" * 5000, "ERROR OUT OF RANGE"),   # beyond int()'s 4 300 digits
                ("!UT-5", "ERROR WRONG FORMAT"),
                ("!UT4294967296", "ERROR OUT OF RANGE"),      # 2^32: the modem's time is 32 bits
                ("!UT\u00b2".encode("utf-8"), "ERROR WRONG FORMAT"),  # a digit to str.isdigit, not to int()
                ("!AL" + "9" * 5000, "ERROR OUT OF RANGE"),   # a ValueError in the loop before
                ("!ZL" + "1" * 30, "ERROR OUT OF RANGE"),
                ("!AR-" + "9" * 5000, "ERROR OUT OF RANGE"),
                ("!RI\u0663".encode("utf-8"), "ERROR WRONG FORMAT"),
                ("?AL", "4"),                                 # nothing was taken
                ("!UT4294967295", "OK")]:
            assert modem.command(command) == answer, command
        assert int(modem.command("?UT")) >= 4294967295
        modem.close()
        assert daemon.status()["class"] == "STATUS"
    finally:
        output = stopped(daemon)
    assert "Traceback" not in output, output


def test_evologics_emulator_serves_a_bounded_number_of_tcp_clients(tmp_path):
    """The 1 500 clients of issue 23: at most eight at once, a ninth served in the place of the one quiet
    longest; those that left free their place (and their protocol state: 300 come and go, and eight
    are served again, none closed for another)."""
    port = free_port()
    daemon, _ = evologics_daemon(tmp_path, port)
    try:
        for _ in range(300):
            socket.create_connection(("127.0.0.1", port), timeout=30).close()
        clients = [AtClient(port) for _ in range(MAX_TCP_CLIENTS)]
        for client in clients:  # each is served (and so was accepted before the next one connects)
            assert client.command("?AL") == "4"
        extra = AtClient(port)
        assert extra.command("?AL") == "4"
        assert clients[0].closed_by_peer(timeout=60)  # the one quiet longest made room
        rest = clients[1:] + [extra]
        assert all(client.command("?AL") == "4" for client in rest)  # the others are undisturbed
        rest.pop(0).close()
        late = AtClient(port)  # in the place the one that left freed, though its close may not be read yet
        assert late.command("?AL") == "4"
        assert all(client.command("?AL") == "4" for client in rest)
        for client in [*rest, late, clients[0]]:
            client.close()
    finally:
        output = stopped(daemon)
    assert "(1 closed so far)" in output and "(2 closed so far)" not in output
    assert "Traceback" not in output


def test_idle_tcp_hosts_do_not_keep_the_labs_software_out_and_the_port_is_loopback(tmp_path):
    """Issue 37 item 6: 8 connections that never said anything took every place of an emulated modem's
    TCP port, and the lab's own software was closed at once.  Now the newcomer is served and the host
    that has been quiet longest makes room; one that talks keeps its place.  The port listens on
    loopback only (as docs/security.md says: any local user may connect, as anyone on a real modem's
    network may)."""
    port = free_port()
    daemon, _ = evologics_daemon(tmp_path, port)
    try:
        assert listening_addresses(port) == ["127.0.0.1"]
        strangers = idle(port, sources=["127.0.0.1"], per_address=MAX_TCP_CLIENTS)
        lab = AtClient(port)
        assert lab.command("?AL") == "4"  # served: the quietest stranger made room
        assert [closed_by_peer(sock) for sock in strangers] == [True] + [False] * (MAX_TCP_CLIENTS - 1)
        more = idle(port, sources=["127.0.0.1"], per_address=MAX_TCP_CLIENTS - 1)
        assert lab.command("?AL") == "4"  # the lab's software talked since: the older strangers went
        assert all(closed_by_peer(sock) for sock in strangers) and not any(closed_by_peer(s) for s in more)
        lab.close()
    finally:
        output = stopped(daemon)
    assert "emulated modem closed the TCP host quiet longest" in output and "Traceback" not in output


# -- a flow's frame size --------------------------------------------------------------------------------


FLOW = """\
channels: {ac: {speed_mps: 1500}}
vehicles: {va: {pose: {static: [0, 0, 0]}}, vb: {pose: {static: [10, 0, 0]}}}
links: {a: {vehicle: va, address: 1}, b: {vehicle: vb, address: 2}}
flows:
  - {from: a, to: b, size_bytes: SIZE, interval_s: 1}
"""


@pytest.mark.parametrize("size", ["1.7976931348623157e+308", "1e300", str(MAX_FRAME_BYTES + 1), "1e400"])
def test_a_flows_frame_size_has_a_stated_maximum(size):
    with pytest.raises(SceneError) as caught:
        load_scene_text(FLOW.replace("SIZE", size), "flows.yaml")
    assert str(caught.value).startswith("flows.yaml:5: flows[0].size_bytes: must be")
    assert len(str(caught.value)) < 200


def test_a_flow_of_the_largest_frame_is_accepted():
    scene = load_scene_text(FLOW.replace("SIZE", str(MAX_FRAME_BYTES)), "flows.yaml")
    assert scene.flows[0].size_bytes == MAX_FRAME_BYTES == 1048576


# -- hilgate app's parameters and Zenoh endpoints -------------------------------------------------------


APP = """\
from hilgate.app import Application


class Quiet(Application):
    pass
"""


@pytest.mark.parametrize("value,words", [
    ("[" * 20000 + "]" * 20000, "nested deeper than 64 levels"),   # a RecursionError after 16 s before
    ("9" * 100000, "a number longer than 1000 characters"),       # a ValueError before
    ("{a: " * 5000 + "1" + "}" * 5000, "nested deeper than 64 levels"),
])
def test_app_parameters_are_read_within_the_limits_of_a_scene(tmp_path, value, words):
    (tmp_path / "quiet.py").write_text(APP)
    result = hilgate("app", "quiet.py:Quiet", "--link", "nosuchlink", "--param", f"x={value}",
                     "--runtime-dir", str(tmp_path / "rt"), cwd=str(tmp_path))
    assert result.returncode == 2, result.stderr
    line = one_error_line(result)
    assert line.startswith("hilgate: --param x:") and words in line and len(line) < 300


def test_app_parameters_that_are_not_yaml_stay_text(tmp_path):
    """Only a broken limit is an error: what YAML cannot read is still the text it was (the app then
    fails to reach its link, which says the parameters were taken)."""
    (tmp_path / "quiet.py").write_text(APP)
    result = hilgate("app", "quiet.py:Quiet", "--link", "nosuchlink", "--param", "x=a: b: c", "--param", "y=[1, 2]",
                     "--runtime-dir", str(tmp_path / "rt"), cwd=str(tmp_path))
    assert result.returncode == 1 and "nosuchlink" in one_error_line(result)


@pytest.mark.parametrize("args", [
    ("app", "quiet.py:Quiet", "--link", "x", "--zenoh", '{"a":'),
    ("app", "quiet.py:Quiet", "--link", "x", "--zenoh", "foo/bar"),
    ("app", "quiet.py:Quiet", "--link", "x", "--zenoh", "tcp/127.0.0.1:7447", "--zenoh-prefix", "a b"),
    ("run", "--zenoh-connect", '{"a":'),
    ("run", "--zenoh-listen", "tcp/ 1"),
])
def test_zenoh_endpoints_are_checked_as_arguments(tmp_path, args):
    (tmp_path / "quiet.py").write_text(APP)
    result = hilgate(*args, cwd=str(tmp_path))
    assert result.returncode == 2, result.stderr
    assert "Zenoh endpoint" in one_error_line(result) or "key prefix" in result.stderr


# -- the S100 emulator under a flood --------------------------------------------------------------------


def s100_scene(tmp_path, ea: str, eb: str, baud: int, rtscts: bool) -> str:
    flow = str(rtscts).lower()
    return TWO_VEHICLES.format(links=f"""\
  {ea}: {{vehicle: va, address: 1, bitrate_bps: 1e6, packet: simple:20,
         emulate: {{protocol: s100, pty: {tmp_path / 'a'}, baud: {baud}, rtscts: {flow}}}}}
  {eb}: {{vehicle: vb, address: 2, bitrate_bps: 1e6, packet: simple:20,
         emulate: {{protocol: s100, pty: {tmp_path / 'b'}, baud: {baud}, rtscts: {flow}}}}}""")


def open_raw(path) -> int:
    fd = os.open(str(path), os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    os.set_blocking(fd, False)
    return fd


def rss_bytes(pid: int) -> int:
    with open(f"/proc/{pid}/status") as handle:
        for line in handle:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


@pytest.mark.parametrize("rtscts", [True, False])
def test_a_flood_into_the_s100_pty_waits_for_the_serial_line(tmp_path, rtscts):
    """16 MB offered at once at 9600 baud: the emulator reads no more than 2 s of its line ahead, so
    the pty's kernel buffer fills and the writer is refused (EAGAIN) instead of the daemon keeping the
    flood (issue 23: +0.37 MB per MB; with RTS/CTS about 1 MB per MB)."""
    ea, eb = unique("fa"), unique("fb")
    daemon = Daemon(tmp_path, s100_scene(tmp_path, ea, eb, 9600, rtscts), [ea, eb])
    try:
        daemon.wait_for("READY=1")
        a, b = open_raw(tmp_path / "a"), open_raw(tmp_path / "b")
        before = rss_bytes(daemon.process.pid)
        chunk = b"\x00flood" * 1000
        accepted = offered = 0
        refused_since = None
        while offered < 16 << 20:
            try:
                accepted += os.write(a, chunk)
                refused_since = None
            except BlockingIOError:
                refused_since = refused_since or time.monotonic()
                if time.monotonic() - refused_since > 2.0:  # the writer is held back: the flood is over
                    break
                time.sleep(0.01)
            offered += len(chunk)
            try:
                os.read(b, 1 << 16)  # the far side reads what arrives
            except BlockingIOError:
                pass
        grown = rss_bytes(daemon.process.pid) - before
        assert accepted < 1 << 20, f"the emulator took {accepted} bytes of the flood"
        assert grown < 8 << 20, f"the daemon grew by {grown} bytes"
        assert daemon.status()["class"] == "STATUS"  # and it still answers
        os.close(a), os.close(b)
    finally:
        output = stopped(daemon)
    assert "Traceback" not in output


def simple20(seq: int) -> bytes:
    import binascii

    payload = seq.to_bytes(2, "big") + b"hilgate-s100-ab"
    assert len(payload) == 17
    return b"\x55" + payload + binascii.crc_hqx(payload, 0).to_bytes(2, "big")


def test_a_long_write_is_timed_by_the_line_across_the_pauses(tmp_path, daemon_of):
    """250 frames written at once (5 500 bytes, 2.9 s of line at 19 200 baud with RTS/CTS): the emulator
    pauses after 2 s worth, resumes while the line is still busy, and every frame reaches the channel
    exactly one line time (22 bytes of 10 bits) after the one before, as without the pauses."""
    ea, eb = unique("la"), unique("lb")
    daemon = daemon_of(s100_scene(tmp_path, ea, eb, 19200, True), [ea, eb])
    a = os.open(str(tmp_path / "a"), os.O_RDWR | os.O_NOCTTY)
    tty.setraw(a)
    b = open_raw(tmp_path / "b")
    frames = [simple20(i) for i in range(250)]
    data = b"".join(f + b"\r\n" for f in frames)
    os.write(a, data)  # blocking: the kernel takes it while the emulator reads
    received = b""
    deadline = time.monotonic() + 120  # a hang guard: 2.9 s of line each way
    while len(received) < len(data) and time.monotonic() < deadline:
        try:
            received += os.read(b, 1 << 16)
        except BlockingIOError:
            time.sleep(0.05)
    assert received == data
    os.close(a), os.close(b)
    daemon.stop()
    enq = [e["t"] for e in daemon.trace_events() if e.get("link") == ea and e["ev"] == "enq"]
    assert len(enq) == 250
    gaps = [later - earlier for earlier, later in zip(enq, enq[1:])]
    assert max(abs(gap - 22 * 10 / 19200) for gap in gaps) <= 2e-9  # the trace rounds to 1 ns
