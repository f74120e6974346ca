"""The sans-I/O codecs alone: dccomms packet classes and hilgate's socket framing.

Exact values come from shared/protocols/gli-dccomms.md (checked there against the real C++
programs); hypothesis feeds random and mutated bytes and only the codecs' own errors may come out.
"""

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hilgate.gli import wire
from hilgate.core.packets import PacketError, crc16, crc32, packet_class


def test_crc_check_values():
    assert crc16(b"123456789") == 0x31C3  # CRC-16/XMODEM
    assert crc32(b"123456789") == 0x89A1897F  # dccomms' Checksum::crc32


@pytest.mark.parametrize("name,body", [("vl1b", 271), ("vl2b", 2065), ("dlf16", 2068), ("dlf32", 2070),
                                       ("simple:20", 32)])
def test_queue_body_sizes_are_dccomms(name, body):
    assert packet_class(name).body_size == body


def test_simple_packet_bytes_match_the_s100_bridge():
    # dccomms' S100 bridge on a pty wrote 55 41..51 A6 72 for a 20-byte SimplePacket
    assert packet_class("simple:20").encode(bytes(range(0x41, 0x52))) == bytes.fromhex(
        "55" + bytes(range(0x41, 0x52)).hex() + "a672")


def test_data_link_frame_layout_and_addresses():
    dlf = packet_class("dlf16")
    real = dlf.encode(b"abc", src=3, dst=7)
    assert real[:6] == b"\x55\x55\x07\x03\x00\x03" and real[6:9] == b"abc"
    assert crc16(real[2:]) == 0  # residue check over dst..FCS
    decoded = dlf.decode_body(dlf.encode_body(real, 9, 99, 99))
    assert (decoded.src, decoded.dst, decoded.seq, decoded.payload) == (3, 7, 9, b"abc")
    dlf32 = packet_class("dlf32")
    assert crc32(dlf32.encode(b"abc", 1, 2)[2:]) == 0


def test_virtual_area_is_little_endian_seq_src_dst():
    vl2b = packet_class("vl2b")
    body = vl2b.encode_body(vl2b.encode(b"hi"), 0x01020304, 5, 6)
    assert body[2053:] == struct.pack("<III", 0x01020304, 5, 6)
    assert vl2b.decode_body(body).dst == 6
    wide = vl2b.encode_body(vl2b.encode(b"hi"), 1, 0xFFFFFFFF, 300)
    assert vl2b.decode_body(wide).dst == 255 and vl2b.decode_body(wide).src == 255  # beyond 254: broadcast


@pytest.mark.parametrize("mutate,reason", [
    (lambda b: b[:-1], "size"),
    (lambda b: b"\x54" + b[1:], "preamble"),
    (lambda b: b[:1] + b"\x09\x00" + b[3:], "length"),
    (lambda b: b[:3] + b"H" + b[4:], "crc"),
])
def test_bad_frames_say_why(mutate, reason):
    vl2b = packet_class("vl2b")
    body = vl2b.encode_body(vl2b.encode(b"hello"), 1, 1, 2)
    with pytest.raises(PacketError) as info:
        vl2b.decode_body(mutate(body))
    assert info.value.reason == reason


def test_payload_too_large_is_refused():
    with pytest.raises(PacketError, match="do not fit"):
        packet_class("vl1b").encode(b"x" * 256)


CLASSES = ["vl1b", "vl2b", "dlf16", "dlf32", "simple:20", "raw"]


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(CLASSES), st.binary(max_size=300), st.integers(0, 2**32 - 1))
def test_round_trip_any_payload(name, payload, seq):
    cls = packet_class(name)
    payload = payload[: cls.max_payload]
    real = cls.encode(payload, src=1, dst=2)
    assert len(real) == cls.real_length(len(payload))
    decoded = cls.decode_body(cls.encode_body(real, seq, 1, 2))
    assert decoded.real == real
    assert decoded.payload[: len(payload)] == payload


@settings(max_examples=1000, deadline=None)
@given(st.sampled_from(CLASSES), st.data())
def test_fuzz_decoders_raise_only_packet_errors(name, data):
    cls = packet_class(name)
    good = cls.encode_body(cls.encode(b"payload", 1, 2), 1, 1, 2)
    if data.draw(st.booleans()):
        body = bytearray(good)
        for _ in range(data.draw(st.integers(1, 8))):
            body[data.draw(st.integers(0, len(body) - 1))] = data.draw(st.integers(0, 255))
        body = bytes(body)
    else:
        body = data.draw(st.binary(max_size=cls.body_size + 20))
    try:
        cls.decode_body(body)
    except PacketError:
        pass


def test_wire_round_trip_and_split_reads():
    messages = (wire.encode_json(wire.HELLO, {"link": "x"}) + wire.encode_send(7, b"a\nb\0")
                + wire.encode_recv(1, 2, 12.5, b"data") + wire.encode_state(True))
    decoder = wire.Decoder()
    out = []
    for i in range(len(messages)):  # one byte at a time
        out += decoder.feed(messages[i:i + 1])
    assert [kind for kind, _ in out] == [wire.HELLO, wire.SEND, wire.RECV, wire.STATE]
    assert wire.decode_json(out[0][1]) == {"link": "x"}
    assert wire.decode_send(out[1][1]) == (7, b"a\nb\0")
    assert wire.decode_recv(out[2][1]) == (1, 2, 12.5, b"data")
    assert decoder.pending == 0


@pytest.mark.parametrize("junk", [b"\x00\x00\x00\x00\x01", b"\xff\xff\xff\xff\x01"])
def test_wire_refuses_bad_lengths(junk):
    with pytest.raises(wire.WireError):
        wire.Decoder().feed(junk)


@settings(max_examples=1000, deadline=None)
@given(st.lists(st.binary(max_size=40), max_size=8))
def test_fuzz_wire_decoder_raises_only_wire_errors(chunks):
    decoder = wire.Decoder()
    try:
        for chunk in chunks:
            for kind, body in decoder.feed(chunk):
                if kind == wire.SEND:
                    wire.decode_send(body)
                elif kind == wire.RECV:
                    wire.decode_recv(body)
                elif kind in (wire.HELLO, wire.COMMAND):
                    wire.decode_json(body)
    except wire.WireError:
        pass
