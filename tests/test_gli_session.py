"""The GLI protocols without I/O: the socket session (HELLO/WELCOME, who may say what) and the dccomms
queue protocol (type byte, REQ_STATE, READY/BUSY without repeats), as h11 tests its connection."""

import json

import pytest

from hilgate.core.packets import packet_class
from hilgate.gli import wire
from hilgate.gli.queue_protocol import (
    CMD_STATE, FRAME, NOTBUILT, REQ_STATE, FrameIn, Ignored, QueueProtocol, Refused, StateRequest,
)
from hilgate.gli.session import Command, Hello, Send, Session, WireError


def hello(link: str) -> bytes:
    return wire.encode_json(wire.HELLO, {"link": link})


def test_a_tcp_client_must_say_hello_before_anything_else():
    session = Session()
    with pytest.raises(WireError, match="say HELLO first"):
        list(session.receive(wire.encode_send(2, b"x")))


def test_hello_then_send_and_command_in_one_read():
    session = Session()
    events = session.receive(hello("la") + wire.encode_send(2, b"hi") + wire.encode_json(wire.COMMAND, {"class": "POSE"}))
    assert next(events) == Hello("la", first=True)
    session.bound = True  # the daemon accepted the link: the next messages are judged after that
    assert list(events) == [Send(2, b"hi"), Command({"class": "POSE"})]


def test_a_links_own_socket_is_bound_to_it_and_refuses_another_link():
    session = Session("la")
    session.bound = True
    assert list(session.receive(wire.encode_send(255, b""))) == [Send(255, b"")]
    assert list(session.receive(hello("la"))) == [Hello("la", first=True)]
    assert list(session.receive(hello("la"))) == [Hello("la", first=False)]  # welcomed once
    with pytest.raises(WireError, match="belongs to link 'la'"):
        list(session.receive(hello("lb")))


@pytest.mark.parametrize("message, error", [
    (wire.encode(wire.HELLO, b"[1]"), "HELLO needs"),
    (wire.encode(wire.HELLO, b'{"link":' * 100 + b"1" + b"}" * 100), "nested deeper"),
    (wire.encode(wire.RECV, b""), "unexpected message type 4"),
    (b"\x00\x00\x00\x00\x01", "bad message length 0"),
])
def test_protocol_violations_are_wire_errors(message, error):
    with pytest.raises(WireError, match=error):
        list(Session("la").receive(message))


def test_a_client_that_left_mid_frame_is_seen():
    session = Session("la")
    list(session.receive(wire.encode_send(2, b"hello")[:5]))
    assert session.pending == 5


def test_the_queue_protocol_decodes_and_refuses_without_a_queue():
    packet = packet_class("vl2b")
    protocol = QueueProtocol(packet)
    assert not protocol.attended
    assert protocol.receive(bytes([REQ_STATE])) == StateRequest()
    assert protocol.attended  # any message shows an application is there
    body = packet.encode_body(packet.encode(b"hi", 1, 2), 7, 1, 2)
    event = protocol.receive(bytes([FRAME]) + body)
    assert isinstance(event, FrameIn) and event.decoded.payload == b"hi" and event.decoded.seq == 7
    assert protocol.receive(bytes([FRAME]) + body[:-1]) == Refused("size", len(body))
    assert protocol.receive(bytes([NOTBUILT])) == Ignored()
    assert protocol.receive(b"") == Refused("size", 0)
    assert protocol.receive(b"\x09") == Refused("type", 1)


def test_ready_and_busy_are_said_once_per_change():
    protocol = QueueProtocol(packet_class("vl2b"))
    busy = protocol.state_change(False)
    assert busy == bytes([CMD_STATE, 0])
    protocol.told(busy)
    assert protocol.state_change(False) is None  # no repeats
    ready = protocol.state_change(True)
    assert ready == bytes([CMD_STATE, 1])
    assert protocol.state_change(True) == ready  # not told yet (the queue was full): says it again
    protocol.told(ready)
    assert protocol.state_change(True) is None
    assert protocol.state_message(True) == ready  # an explicit REQ_STATE is always answered


def test_a_frame_from_the_application_makes_it_busy_in_its_own_eyes():
    """dccomms' WritePacket sets the application's PHY state BUSY before it sends: after any frame
    (even one refused) the next READY must be said again, and a BUSY would be a repeat."""
    packet = packet_class("vl2b")
    protocol = QueueProtocol(packet)
    protocol.told(protocol.state_message(True))
    assert protocol.state_change(True) is None
    body = packet.encode_body(packet.encode(b"hi", 1, 2), 7, 1, 2)
    protocol.receive(bytes([FRAME]) + body)
    assert protocol.state_change(False) is None
    assert protocol.state_change(True) == bytes([CMD_STATE, 1])
    protocol.told(bytes([CMD_STATE, 1]))
    assert protocol.receive(bytes([FRAME]) + body[:-1]) == Refused("size", len(body))
    assert protocol.state_change(True) == bytes([CMD_STATE, 1])
    protocol.told(bytes([CMD_STATE, 1]))
    protocol.receive(bytes([REQ_STATE]))
    assert protocol.state_change(True) is None  # a REQ_STATE is answered, but leaves the state alone


def test_welcome_describes_the_link():
    from hilgate.gli.sockets import welcome

    class Port:
        id, address, packet = "la", 3, packet_class("dlf16")

    assert welcome(Port()) == {"link": "la", "address": 3, "packet": "dlf16", "max_payload": 2048,
                               "version": wire.VERSION}
    json.dumps(welcome(Port()))
