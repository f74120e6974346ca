"""What daemons tell each other, without any network: transmissions and poses as bytes, and back."""

from __future__ import annotations

import io
import json
import struct
import zlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hilgate.core.backend import AppFrame
from hilgate.core.packets import packet_class
from hilgate.daemon.netcodec import (
    KIND, LINK_NAME, MAX_TRANSMISSION, NetError, ReplayWindow, decode_pose, decode_transmission, encode_pose,
    encode_transmission, to_local,
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


@pytest.mark.parametrize("name", ["simple:20", "dlf16", "raw"])
def test_every_packet_class_crosses_hosts_by_its_name(name):
    """simple:N's name has a colon: read as not a name of its kind, its every frame was refused by the
    other hosts (counted bad_message) and never delivered there."""
    packet = packet_class(name)
    payload = b"\x01" * 17 if name.startswith("simple") else b"hi"
    app = AppFrame(packet.encode(payload, 1, 2), payload, packet, 7, 1, 2, 12.5, None)
    frame = Frame(41, "a", "b", 2, len(app.real), 12.5, app_frame=app)
    frame.src_addr = 1
    back = decode_transmission(encode_transmission("hostA", 5, 1, frame, 12.5, 0.1, None)).frame.app_frame
    assert (back.packet.name, back.real, back.payload) == (name, app.real, app.payload)


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


def _sealed(body: bytes) -> bytes:
    """``body`` with a CRC that matches: damage an attacker made on purpose, past the CRC, to the fields."""
    return body + struct.pack(">I", zlib.crc32(body))


def test_another_version_and_trailing_bytes_are_refused():
    blob = _valid_blobs()[1]
    with pytest.raises(NetError, match="another hilgate version"):
        decode_transmission(b"\x00" + blob[1:])  # what the JSON format (version 1) started with
    with pytest.raises(NetError, match="damaged"):
        decode_transmission(blob + b"x")
    with pytest.raises(NetError, match="trailing"):
        decode_transmission(_sealed(blob[:-4] + b"x"))
    assert decode_transmission(blob).frame.ack is None and decode_transmission(_valid_blobs()[0]).frame.ack == 3


def test_every_bit_flipped_is_refused_as_damaged():
    """The issue's mutated copies: 3 250 of 20 000 were delivered with corrupted payloads.  One bit
    flipped anywhere (every one of them, both messages) is refused, counted ``damaged``."""
    refused = 0
    for blob in _valid_blobs():
        for i in range(1, len(blob)):  # (byte 0 is the version: refused as another version)
            for bit in range(8):
                damaged = bytearray(blob)
                damaged[i] ^= 1 << bit
                with pytest.raises(NetError) as error:
                    decode_transmission(bytes(damaged))
                assert error.value.cause == "damaged"
                refused += 1
    assert refused == sum(len(blob) - 1 for blob in _valid_blobs()) * 8


def test_a_message_longer_than_any_transmission_is_refused_unread():
    with pytest.raises(NetError, match="longer than any transmission"):
        decode_transmission(b"\x03" + bytes(8 << 20))  # the 8 MB message
    assert MAX_TRANSMISSION >= len(_valid_blobs()[0])


def _trace_lines(message) -> list[str]:
    """What the trace writes of a frame from another host (the recorder's own formatting)."""
    from hilgate.sim.recorder import Recorder

    class Modem:
        json_id, queued_bytes = json.dumps("here"), 0

    out = io.StringIO()
    recorder = Recorder(out)
    for frame in (message.frame, message.frame.ref):
        if frame is not None:
            recorder._line(1.0, "rx", Modem(), frame, "col")
            recorder.event({"t": 1.0, "ev": "drop", "src": message.host, "cause": "replay", "kind": frame.kind})
    return out.getvalue().splitlines()


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([0, 1]), st.sampled_from(["kind", "src", "dst", "host", "packet"]),
       st.text(min_size=1, max_size=40))
def test_names_from_another_host_are_checked_so_the_trace_stays_json(which, field, text):
    """Kinds, link ids, host and packet names with quotes, NUL, newlines or any Unicode, sealed with a
    right CRC: refused, or names of their kind; and whatever is read makes trace lines that parse."""
    vl2b = packet_class("vl2b")
    app = AppFrame(vl2b.encode(b"hi", 1, 2), b"hi", vl2b, 7, 1, 2, 12.5, None)
    names = {"kind": "data", "src": "a", "dst": "b", "host": "hostA", "packet": "vl2b", field: text}
    frame = Frame(41, names["src"], names["dst"], 2, len(app.real), 12.5, app_frame=app, kind=names["kind"])
    frame.src_addr = 1
    app.packet = type("P", (), {"name": names["packet"]})()
    try:
        blob = encode_transmission(names["host"], 5, 1, frame, 12.5, 0.1, None)
    except ValueError:
        return  # (too long to encode)
    try:
        message = decode_transmission(blob)
    except NetError:
        return
    assert KIND.fullmatch(message.frame.kind) and LINK_NAME.fullmatch(message.frame.src_link)
    assert LINK_NAME.fullmatch(message.frame.dst_link) and LINK_NAME.fullmatch(message.host)
    for line in _trace_lines(message):
        json.loads(line)


@settings(max_examples=400, deadline=None)
@given(st.sampled_from([0, 1]), st.lists(st.tuples(st.integers(0, 400), st.integers(0, 255)), min_size=1, max_size=6))
def test_fields_damaged_past_the_crc_are_refused_or_read_into_valid_trace_lines(which, flips):
    blob = bytearray(_valid_blobs()[which][:-4])
    for at, value in flips:
        if at < len(blob):
            blob[at] = value
    try:
        message = decode_transmission(_sealed(bytes(blob)))
    except NetError as error:
        assert error.cause == "bad_message"
        return
    for line in _trace_lines(message):
        json.loads(line)


def test_the_replay_window_takes_each_number_once_per_session():
    window = ReplayWindow()
    assert [window.admit("s1", 100, n) for n in (1, 2, 3)] == [0, 0, 0]
    assert window.admit("s1", 100, 2) == "replay"                # seen
    assert window.admit("s1", 100, 7) == 3                       # 4, 5, 6 skipped: gaps
    assert window.admit("s1", 100, 5) == 0                       # late, never seen: taken once
    assert window.admit("s1", 100, 5) == "replay"
    assert window.admit("s1", 100, 7 + ReplayWindow.MAX_JUMP + 1) == "bad_message"  # numbers made up far ahead
    assert window.admit("s1", 100, 7 + ReplayWindow.WINDOW) == ReplayWindow.WINDOW - 1
    assert window.admit("s1", 100, 7) == "replay"                # older than the window
    # the host restarts: a new session (later epoch) counts from 1 again, no gap of 10^20
    assert window.admit("s2", 200, 1) == 0 and window.admit("s2", 200, 2) == 0
    assert window.admit("s1", 100, 9999) == "replay"             # the earlier session's, replayed
    # the host was down: its numbers went on for the others, a jump ahead is no gap (once)
    window.resync = True
    assert window.admit("s2", 200, 10_000_000_000) == 0
    assert window.admit("s2", 200, 10_000_000_002) == 1


def test_a_daemon_that_starts_while_another_host_runs_hears_its_numbers_without_a_gap():
    """Its window was not there for the numbers before the first it hears: before, a restarted host
    counted every message the other had sent since its own start as a gap (traced net_gap, n in the
    thousands), and past MAX_JUMP (16.7 million messages: two days at 100 a second) refused them all."""
    window = ReplayWindow()
    assert window.admit("s1", 100, 5000) == 0
    assert window.admit("s1", 100, 5002) == 1  # from there on, gaps are gaps
    late = ReplayWindow()
    assert late.admit("s1", 100, ReplayWindow.MAX_JUMP + 10) == 0
    assert late.admit("s1", 100, ReplayWindow.MAX_JUMP + 11) == 0


def test_a_forged_session_of_a_later_epoch_leaves_the_hosts_own_session_heard():
    """Issue 37: a thief with the host's key puts one message of a session a nanosecond newer.  The
    host's own session (its daemon alive) goes on; a session whose daemon is gone does not."""
    window = ReplayWindow()
    assert [window.admit("honest", 100, n, alive=True) for n in (1, 2, 3)] == [0, 0, 0]
    assert window.admit("forged", 101, 1) == 0  # (a stolen key forges: taken)
    assert [window.admit("honest", 100, n, alive=True) for n in (4, 5)] == [0, 0]
    assert window.admit("honest", 100, 5, alive=True) == "replay"  # its own window, as before
    assert window.admit("honest", 100, 6, alive=False) == "replay"  # an older start whose daemon is gone
    assert window.admit("honest", 99, 7, alive=True) == "bad_message"  # not that session's epoch


def test_a_number_far_ahead_costs_the_honest_run_nothing():
    window = ReplayWindow()
    assert [window.admit("s", 100, n) for n in range(1, 11)] == [0] * 10
    far = 10 + ReplayWindow.MAX_JUMP - 1
    assert window.admit("s", 100, far) == far - 11  # a run of its own (the gap counted, as Zenoh's would be)
    assert [window.admit("s", 100, n) for n in range(11, 2000)] == [0] * 1989  # the honest run goes on
    assert window.admit("s", 100, far) == "replay" and window.admit("s", 100, 1500) == "replay"
    assert window.admit("s", 100, 5) == "replay"  # below every run's window
    # the honest numbers reach the forged one (its window: gaps counted at the jump): each is taken once,
    # the forged number itself is the one lost
    assert [window.admit("s", 100, n) for n in range(far - 3, far + 3)] == [0, 0, 0, "replay", 0, 0]


def test_what_is_refused_takes_no_place():
    """A refused message (a jump too far, a second session beside the newest) is not remembered: a thief
    cannot push the host's session out with messages that are refused anyway."""
    window = ReplayWindow()
    assert window.admit("honest", 100, 1) == 0
    for i in range(2 * ReplayWindow.SESSIONS):
        assert window.admit(f"f{i}", 100 + i + 1, ReplayWindow.MAX_JUMP + 5) == "bad_message"
    assert list(window.sessions) == ["honest"] and window.newest == 100
    assert window.admit("other", 100, 1) == "replay"  # beside the newest, not alive
    assert window.admit("other", 100, 1, alive=True) == 0  # …unless its daemon holds the host's token


def test_a_restarted_host_is_heard_whatever_epoch_was_forged():
    window = ReplayWindow()
    assert window.admit("first", 100, 1, alive=True) == 0
    assert window.admit("forged", 10_000, 1) == 0  # a start later than the host's next one
    assert window.admit("restarted", 500, 1) == "replay"  # (its token not heard yet)
    assert window.admit("restarted", 500, 1, alive=True) == 0  # its daemon holds the host's token: heard
    assert [window.admit("restarted", 500, n, alive=True) for n in (2, 3)] == [0, 0]


def test_a_session_that_started_before_the_window_listened_is_heard_from_its_first_number():
    """Sessions side by side (issue 37) and a daemon that starts while the others run (issue 36): a
    forged message heard first must not leave the host's own session, older than the window, counted
    from 0 (a gap of every earlier number, past MAX_JUMP all refused)."""
    window = ReplayWindow(since_ns=1000)
    assert window.admit("forged", 1500, 1) == 0
    far = ReplayWindow.MAX_JUMP + 10
    assert window.admit("honest", 500, far, alive=True) == 0  # started before the window listened
    assert window.admit("honest", 500, far + 2, alive=True) == 1  # from there on, gaps are gaps
    assert window.admit("honest", 500, far - 5, alive=True) == 0  # late, within the window: taken once
    assert window.admit("honest", 500, 3, alive=True) == "replay"  # before its first number heard
    # a session that started after the window listened was heard from its start: what it skipped is a gap
    assert window.admit("restarted", 2000, 5, alive=True) == 4
    assert window.admit("later", 3000, ReplayWindow.MAX_JUMP + 5, alive=True) == "bad_message"
