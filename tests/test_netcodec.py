"""What daemons tell each other, without any network: transmissions and poses as bytes, and back."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hilgate.core.backend import AppFrame
from hilgate.core.packets import packet_class
from hilgate.daemon.netcodec import (
    NetError, decode_pose, decode_transmission, encode_pose, encode_transmission, to_local,
)
from hilgate.models.frame import CTS, Frame


def test_a_transmission_comes_back_whole_with_its_application_frame_and_served_frame():
    vl2b = packet_class("vl2b")
    app = AppFrame(vl2b.encode(b"hello\x00\r\n", 1, 2), b"hello\x00\r\n", vl2b, 7, 1, 2, 12.5, {"kind": "im", "ack": False})
    data_frame = Frame(41, "a", "b", 2, len(app.real), 12.5, app_frame=app)
    data_frame.src_addr = 1
    cts = Frame(42, "b", "a", 1, 6, 13.0, kind=CTS, ref=data_frame)
    cts.src_addr = 2
    blob = encode_transmission("hostB", 1_795_000_000_123_456_789, 9, cts, 13.25, 0.048, (150.0, 0.0, -5.5))
    message = decode_transmission(blob)
    assert (message.host, message.epoch_ns, message.number) == ("hostB", 1_795_000_000_123_456_789, 9)
    assert (message.t, message.duration, message.position) == (13.25, 0.048, (150.0, 0.0, -5.5))
    frame = message.frame
    assert (frame.id, frame.src_link, frame.dst_link, frame.dst_addr, frame.src_addr, frame.size, frame.kind,
            frame.t0) == (42, "b", "a", 1, 2, 6, CTS, 13.0)
    assert message.ref_key == ("a", 41) and frame.ref.size == len(app.real)

    blob = encode_transmission("hostA", 5, 1, data_frame, 12.5, 0.1, None)
    app_back = decode_transmission(blob).frame.app_frame
    assert (app_back.real, app_back.payload, app_back.packet.name, app_back.seq, app_back.src, app_back.dst,
            app_back.t0, app_back.meta) == (app.real, app.payload, "vl2b", 7, 1, 2, 12.5, {"kind": "im", "ack": False})


def test_model_times_cross_hosts_through_their_epochs():
    assert to_local(10.0, 2_000_000_000, 1_000_000_000) == 11.0   # the sender started a second later
    assert to_local(10.0, 1_000_000_000, 1_500_000_000) == 9.5


def test_a_pose_comes_back_and_a_bad_one_is_refused():
    pose = decode_pose(encode_pose("B", 3, "rov", 1.5, (1.0, 2.0, 3.0), None))
    assert pose == {"host": "B", "epoch_ns": 3, "vehicle": "rov", "t": 1.5, "position": (1.0, 2.0, 3.0),
                    "velocity": None}
    for bad in (b"", b"[]", b'{"h": "B"}', b'{"h": "B", "e": 1, "v": "r", "t": 1, "p": [1, 2]}',
                b'{"h": "B", "e": 1, "v": "r", "t": 1e999, "p": null}', b"\xff" * 10):
        with pytest.raises(NetError):
            decode_pose(bad)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_any_bytes_are_a_transmission_or_a_net_error(data):
    try:
        decode_transmission(data)
    except NetError:
        pass


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.sampled_from(["h", "e", "n", "l", "i", "dl", "da", "sa", "s", "t", "d", "k", "q", "t0",
                                        "p", "r", "a"]),
                       st.one_of(st.none(), st.integers(), st.floats(), st.text(max_size=5),
                                 st.lists(st.floats(), max_size=4), st.dictionaries(st.text(max_size=3),
                                                                                   st.integers(), max_size=3))))
def test_hostile_headers_are_net_errors(header):
    import json
    import struct

    blob = json.dumps(header).encode()
    try:
        decode_transmission(struct.pack(">I", len(blob)) + blob + b"tail")
    except NetError:
        pass
