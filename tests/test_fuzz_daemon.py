"""Fuzzing the running daemon through its three doors: control socket, GLI sockets, GLI queues.

The only allowed outcomes are the documented answers (an ERROR, a refused frame counted in the
status), never a traceback, a hang or a dead daemon; and a well-behaved application on another link
keeps getting its frames.  Bounded to seconds in CI; ``make fuzz`` runs them for minutes.
"""

import json
import os
import socket

import posix_ipc
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from daemon_kit import Daemon, quick_scene, unique
from fuzzkit import examples
from hilgate.gli import wire
from hilgate.client import Link

@pytest.fixture(scope="module")
def daemon(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fuzz")
    a, b = unique("a"), unique("b")
    running = Daemon(tmp, quick_scene("fuzz", a, b, distance_m=1, bitrate_bps=1e7, speed_mps=1e9), [a, b])
    running.a, running.b = a, b
    try:
        running.wait_for("READY=1")
        yield running
        assert "Traceback" not in running.output()
    finally:
        running.close()


def still_works(daemon) -> None:
    """A well-behaved application still sends and receives through the daemon."""
    with Link.open(daemon.a, runtime_dir=daemon.runtime) as sender, Link.open(daemon.b, runtime_dir=daemon.runtime) as receiver:
        sender.send(b"canary", dst=2)
        message = receiver.recv(timeout=60)
        assert message is not None and message.data == b"canary"


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=20)
requests = st.one_of(
    st.dictionaries(st.sampled_from(["class", "interval_s", "enable", "x"]), json_values, max_size=3).map(json.dumps),
    st.fixed_dictionaries({"class": st.sampled_from(["STATUS", "WATCH", "RELOAD", "NOPE"])},
                          optional={"interval_s": json_values, "enable": json_values}).map(json.dumps),
    json_values.map(json.dumps),
    st.text(max_size=200).filter(lambda t: "\n" not in t),
)


@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(lines=st.lists(requests, min_size=1, max_size=5))
@example(lines=['{"class": "WATCH", "enable": false, "interval_s": null}'])  # once went unanswered
@example(lines=['{"class": "WATCH", "interval_s": 0.05}', '{"class": "STATUS"}'])
def test_fuzz_control_requests(daemon, lines):
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(60)
    sock.connect(os.path.join(daemon.runtime, "control.sock"))
    reader = sock.makefile("r")
    try:
        assert json.loads(reader.readline())["class"] == "VERSION"
        for line in lines:
            request = line.encode("utf-8", "surrogatepass")
            if not request.strip() or b"RELOAD" in request:
                continue  # an empty line gets no answer; reloads are tested elsewhere (they take a second)
            sock.sendall(request + b"\n")
            answer = json.loads(reader.readline())
            assert answer["class"] in ("ERROR", "STATUS", "WATCH"), answer
            if '"WATCH"' in line:  # maybe a watch began: stop it, and skip its STATUS lines to the answer
                sock.sendall(b'{"class": "WATCH", "enable": false}\n')
                while answer["class"] != "WATCH" or answer.get("enable") is not False:
                    answer = json.loads(reader.readline())
    finally:
        sock.close()


frames = st.one_of(
    st.binary(max_size=300),
    st.builds(lambda kind, body: wire.encode(kind, body), st.integers(0, 255), st.binary(max_size=200)),
    st.builds(lambda dst, payload: wire.encode_send(dst, payload), st.integers(0, 255), st.binary(max_size=3000)),
)


@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(chunks=st.lists(frames, min_size=1, max_size=6))
def test_fuzz_gli_socket_frames(daemon, chunks):
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(60)
    sock.connect(os.path.join(daemon.runtime, "gli", f"{daemon.a}.sock"))
    try:
        for chunk in chunks:
            try:
                sock.sendall(chunk)
            except (BrokenPipeError, ConnectionResetError):
                break  # refused and disconnected: an allowed outcome
    finally:
        sock.close()
    assert daemon.status()["class"] == "STATUS"


messages = st.one_of(
    st.binary(max_size=64),
    st.builds(lambda body: b"\x00" + body, st.binary(min_size=0, max_size=2100)),
    st.builds(lambda kind: bytes([kind]), st.integers(0, 255)),
)


@settings(max_examples=examples(80), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(batch=st.lists(messages, min_size=1, max_size=8))
def test_fuzz_gli_queue_messages(daemon, batch):
    queue = posix_ipc.MessageQueue(f"/{daemon.a}_tx_dlnk_phy")
    try:
        for message in batch:
            if len(message) > queue.max_message_size:
                message = message[: queue.max_message_size]
            queue.send(message, timeout=60)
    finally:
        queue.close()
    assert daemon.status()["class"] == "STATUS"


def test_after_the_fuzzing_applications_still_talk(daemon):
    still_works(daemon)
    status = {link["id"]: link for link in daemon.status()["links"]}
    assert status[daemon.a]["state"] == "up"
