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


def _valid_blobs() -> list[bytes]:
    vl2b = packet_class("vl2b")
    app = AppFrame(vl2b.encode(b"hi", 1, 2), b"hi", vl2b, 7, 1, 2, 12.5, {"kind": "im"})
    data_frame = Frame(41, "a", "b", 2, len(app.real), 12.5, app_frame=app)
    data_frame.src_addr, data_frame.ack = 1, 3
    cts = Frame(42, "b", "a", 1, 6, 13.0, kind=CTS, ref=data_frame)
    return [encode_transmission("hostA", 5, 1, data_frame, 12.5, 0.1, (1.0, 2.0, 3.0)),
            encode_transmission("hostB", 6, 2, cts, 13.0, 0.05, None)]


@settings(max_examples=400, deadline=None)
@given(st.sampled_from([0, 1]), st.lists(st.tuples(st.integers(0, 400), st.integers(0, 255)), max_size=6),
       st.integers(0, 400))
def test_a_damaged_transmission_is_read_or_refused_never_raised(which, flips, cut):
    """Every field of a real transmission corrupted or cut short: a NetError or a well-formed message."""
    blob = bytearray(_valid_blobs()[which])
    for at, value in flips:
        if at < len(blob):
            blob[at] = value
    try:
        message = decode_transmission(bytes(blob[:len(blob) - cut if cut < len(blob) else len(blob)]))
    except NetError:
        return
    assert message.duration >= 0 and isinstance(message.host, str) and message.frame.size >= 0


def test_another_version_and_trailing_bytes_are_refused():
    blob = _valid_blobs()[1]
    with pytest.raises(NetError, match="another hilgate version"):
        decode_transmission(b"\x00" + blob[1:])  # what the JSON format (version 1) started with
    with pytest.raises(NetError, match="trailing"):
        decode_transmission(blob + b"x")
    assert decode_transmission(blob).frame.ack is None and decode_transmission(_valid_blobs()[0]).frame.ack == 3
