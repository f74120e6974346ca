"""The cheap paths of a frame across hosts, each taken only when its condition holds (issue 31, item 2).

- A Zenoh publisher is skipped while nobody subscribes (``WatchedPublisher.matching``), and used again
  as soon as somebody does: with real Zenoh sessions.
- A transmission carries its application's payload once, as a slice of the real packet, when it is
  one; when it is not, the payload follows the packet: both read back whole.
"""

from __future__ import annotations

import json
import uuid

import pytest

from daemon_kit import free_port, wait_until  # noqa: E402
from hilgate.core.backend import AppFrame
from hilgate.core.packets import packet_class
from hilgate.daemon.netcodec import decode_transmission, encode_transmission
from hilgate.models.frame import Frame

zenoh = pytest.importorskip("zenoh")


def _session(listen: str | None = None, connect: str | None = None):
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", json.dumps([listen] if listen else []))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps([connect]))
    return zenoh.open(config)


def test_a_watched_publisher_is_used_only_while_somebody_subscribes():
    from hilgate.gli.zenoh_door import WatchedPublisher

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    key = f"hilgate-test-{uuid.uuid4().hex[:8]}/link/H/l/recv"
    here, there = _session(listen=endpoint), _session(connect=endpoint)
    try:
        wait_until(lambda: list(here.info.peers_zid()), what="the two sessions to meet")
        publisher = WatchedPublisher(here.declare_publisher(key))
        assert publisher.matching is False  # (a bool: the status object itself is always true)
        got = []
        subscriber = there.declare_subscriber(key, lambda sample: got.append(sample.payload.to_bytes()))
        wait_until(lambda: publisher.matching, what="the publisher to see the subscriber")
        publisher.put(b"seen")
        wait_until(lambda: got, what="the message")
        assert got == [b"seen"]
        subscriber.undeclare()
        wait_until(lambda: publisher.matching is False, what="the publisher to see the subscriber go")
        publisher.undeclare()
    finally:
        there.close()
        here.close()


def _frame(real: bytes, payload: bytes) -> Frame:
    vl2b = packet_class("vl2b")
    frame = Frame(41, "a", "b", 2, len(real), 12.5, app_frame=AppFrame(real, payload, vl2b, 7, 1, 2, 12.5, None))
    frame.src_addr = 1
    return frame


def test_the_payload_is_sent_once_when_it_is_a_slice_of_the_packet_and_else_after_it():
    vl2b = packet_class("vl2b")
    payload = bytes(range(256)) * 8
    real = vl2b.encode(payload, 1, 2)
    assert payload in real
    once = encode_transmission("hostA", 5, 1, _frame(real, payload), 12.5, 0.1, None)
    other = b"\x5a" * len(payload)  # (not in the packet: a class that transforms its payload)
    twice = encode_transmission("hostA", 5, 1, _frame(real, other), 12.5, 0.1, None)
    assert len(twice) - len(once) == len(payload)
    for blob, expected in ((once, payload), (twice, other)):
        app = decode_transmission(blob).frame.app_frame
        assert (app.real, app.payload) == (real, expected)
    empty = decode_transmission(encode_transmission("hostA", 5, 1, _frame(real, b""), 12.5, 0.1, None))
    assert empty.frame.app_frame.payload == b""
