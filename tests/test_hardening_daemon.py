"""The daemon against hostile or broken input: reloads, control requests, GLI clients.  Every item
answers with an error (never a traceback, a hang or silence) and the links keep working."""

import json
import os
import socket
import time

import pytest

from daemon_kit import Daemon, unique


def scene(a: str, b: str, extra_links: str = "", extra: str = "") -> str:
    return f"""\
name: hardening
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {{static: [150, 0, 0]}}}}
links:
  {a}: {{vehicle: va, address: 1, bitrate_bps: 10000, packet: vl2b}}
  {b}: {{vehicle: vb, address: 2, bitrate_bps: 10000, packet: vl2b}}
{extra_links}
trace: {{poses_s: 0}}
{extra}"""


@pytest.fixture
def pair(tmp_path):
    a, b = unique("a"), unique("b")
    daemon = Daemon(tmp_path, scene(a, b), [a, b])
    try:
        daemon.wait_for("READY=1")
        yield daemon, a, b
    finally:
        daemon.close()


def control_connection(daemon):
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(60)
    sock.connect(os.path.join(daemon.runtime, "control.sock"))
    reader = sock.makefile("r")
    assert json.loads(reader.readline())["class"] == "VERSION"
    return sock, reader


def test_a_reload_that_fails_while_applying_is_answered_and_systemd_gets_ready(pair):
    daemon, a, b = pair
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port = busy.getsockname()[1]
    c = unique("c")
    daemon.links.append(c)
    try:
        # valid, but the emulated modem's TCP port is taken: only applying it can find that out
        daemon.scene.write_text(scene(a, b, f"  {c}: {{vehicle: va, address: 3, emulate: {{protocol: evologics, tcp: {port}}}}}"))
        reply = daemon.control({"class": "RELOAD"})
        assert reply["class"] == "RELOAD" and reply["ok"] is False
        assert "\n" not in reply["error"] and "applying" in reply["error"]
        daemon.wait_for("RELOADING=1")
        daemon.wait_for("READY=1")  # systemd is not left at RELOADING=1
        assert "Traceback" not in daemon.output()
        assert daemon.status()["class"] == "STATUS"  # and the daemon still answers
    finally:
        busy.close()


def test_a_scene_is_parsed_off_the_loop_during_a_reload(pair):
    daemon, a, b = pair
    # a valid scene that takes PyYAML a long time (an ignored x- key with a large list)
    padding = "x-pad: [" + ", ".join(str(i) for i in range(60_000)) + "]\n"
    daemon.scene.write_text(scene(a, b) + padding)
    slow, slow_reader = control_connection(daemon)
    fast, fast_reader = control_connection(daemon)
    try:
        slow.sendall(b'{"class": "RELOAD"}\n')
        fast.sendall(b'{"class": "STATUS"}\n')
        status = json.loads(fast_reader.readline())
        slow.settimeout(0)
        try:
            early = slow.recv(1)  # the reload must still be running: the loop was not parsing
        except BlockingIOError:
            early = b""
        assert status["class"] == "STATUS" and early == b""
        slow.settimeout(120)
        assert json.loads(slow_reader.readline()) == {"class": "RELOAD", "ok": True}
    finally:
        slow.close()
        fast.close()
