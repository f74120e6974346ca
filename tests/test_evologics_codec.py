"""The EvoLogics AT codecs and the S100 hunter alone, no port: the edge cases of
shared/protocols/evologics-at.md section 5, and random or mutated bytes (only the codecs' own
protocol errors may come out)."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hilgate.drivers.evologics_codec import (
    AsyncError, AtProtocolError, BadCommand, Command, Data, HostCodec, ModemCodec, Notification, Reply, Unexpected,
)
from hilgate.drivers.s100_codec import FrameHunter, Notice, Skipped, pieces, wire_class
from hilgate.core.packets import Decoded, packet_class

NASTY = b"a,b\r\n\x00+++AT:3:x\r\n"


def feed_bytewise(codec, data):
    events = []
    for i in range(len(data)):
        events += codec.receive_data(data[i:i + 1])
    return events


def test_send_commands_frame_the_payload_by_length():
    im = HostCodec(eol=b"\r").command("*SENDIM", payload=NASTY, fields=(2, "ack"))
    assert im == b"AT*SENDIM,%d,2,ack," % len(NASTY) + NASTY + b"\r"
    assert HostCodec(eol=b"\n").command("*SEND", payload=b"xy", fields=(7,)) == b"AT*SEND,2,7,xy\n"


@pytest.mark.parametrize("payload", [b"hello", NASTY, b"\r\n", b",,,", b"\x00" * 10, b"+++AT", b""])
def test_recvim_payloads_of_any_bytes_split_anywhere(payload):
    line = b"RECVIM,%d,1,2,ack,1000,-40,120,0.00," % len(payload) + payload + b"\r\n"
    for events in (HostCodec().receive_data(line), feed_bytewise(HostCodec(), line)):
        assert events == [Notification("RECVIM", ("%d" % len(payload), "1", "2", "ack", "1000", "-40", "120", "0.00"),
                                       payload, None)]


def test_recv_variants_pid_pbm_ims_burst_and_firmware_1_6():
    data = (b"RECVIM,p0,3,1,2,noack,900,-50,110,0.10,abc\r\n"
            b"RECVPBM,2,4,5,800,-60,101,0.00,hi\r\n"
            b"RECVIMS,2,4,5,123456,800,-60,101,0.00,ok\r\n"
            b"RECV,3,1,2,4000,-45,130,30000,0.00,x,y\r\n"
            b"RECVIM,2,1,2,ack,976,-40,120,90000,0.00,zz\r\n")
    events = HostCodec().receive_data(data)
    assert [(e.name, e.payload, e.pid) for e in events] == [
        ("RECVIM", b"abc", 0), ("RECVPBM", b"hi", None), ("RECVIMS", b"ok", None), ("RECV", b"x,y", None),
        ("RECVIM", b"zz", None)]
    assert len(events[-1].fields) == 9  # the 1.6 layout: bitrate,rssi,int,ptime,vel


def test_notification_between_a_command_and_its_reply():
    codec = HostCodec()
    codec.command("?T")
    events = codec.receive_data(b"DELIVEREDIM,2\r\nRECVSTART\r\n1500\r\n")
    assert events == [Notification("DELIVEREDIM", ("2",)), Notification("RECVSTART", ()), Reply("?T", "1500")]


def test_replies_errors_busy_pending_ok_and_unsolicited_errors():
    codec = HostCodec()
    codec.command("!L", "3")
    codec_events = codec.receive_data(b"ERROR EFAULT\r\n[*]OK\r\n")
    assert codec_events == [AsyncError("EFAULT"), Reply("!L", "[*]OK")]
    assert codec_events[1].ok
    codec.command("*SENDIM", payload=b"x", fields=(2, "ack"))
    assert codec.receive_data(b"BUSY DELIVERING\r\n")[0].error == "BUSY DELIVERING"
    assert codec.receive_data(b"ERROR OVERLOAD\r\n") == [AsyncError("OVERLOAD")]
    assert codec.receive_data(b"OK\r\n") == [Unexpected("OK")]  # nothing in flight


def test_blank_lines_and_multiline_answers():
    codec = HostCodec()
    codec.command("&V")
    events = codec.receive_data(b"\r\nSource Level: 3\r\nPool Size: 16384\r\n\r\n\r\n")
    assert events == [Reply("&V", "Source Level: 3", ("Source Level: 3", "Pool Size: 16384"))]
    codec.command("?P")
    events = codec.receive_data(b"1 100\n2 120\n3 115\r\n")  # ?P: bare LF between its lines
    assert events == [Reply("?P", "1 100\n2 120\n3 115")]


def test_data_mode_escape_frames_raw_data_and_a_held_back_tail():
    codec = HostCodec(data_mode=True)
    codec.command("?T")
    events = codec.receive_data(b"raw bytes+++AT?T:4:1500\r\nmore+++A")
    assert events == [Data(b"raw bytes"), Reply("?T", "1500"), Data(b"more")]
    events = codec.receive_data(b"T:13:DELIVEREDIM,2\r\n+++ATnot an escape")
    assert events[0] == Notification("DELIVEREDIM", ("2",))
    assert b"".join(e.payload for e in events[1:] if isinstance(e, Data)) + b"".join(
        e.payload for e in codec.receive_data(b"\r\n") if isinstance(e, Data)) == b"+++ATnot an escape\r\n"
    body = b"RECVIM,3,1,2,ack,1,-2,3,0.00,\r\n+"
    events = codec.receive_data(b"+++AT:%d:" % len(body) + body + b"\r\n")
    assert events == [Notification("RECVIM", ("3", "1", "2", "ack", "1", "-2", "3", "0.00"), b"\r\n+")]


def test_command_switches_modes():
    codec = HostCodec()
    assert codec.command("O") == b"ATO\r" and codec.data_mode and codec.pending is None
    assert codec.command("?T") == b"+++AT?T\r"
    assert codec.command("C") == b"+++ATC\r" and not codec.data_mode


def test_a_malformed_frame_is_reported_and_skipped():
    events = HostCodec().receive_data(b"RECVIM,x,1,2,ack,1,1,1,0,abc\r\nDELIVEREDIM,3\r\n")
    assert isinstance(events[0], AtProtocolError)
    assert events[-1] == Notification("DELIVEREDIM", ("3",))


# -- modem side ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("eol", [b"\r", b"\n", b"\r\n"])
def test_modem_accepts_every_line_ending(eol):
    codec = ModemCodec()
    data = b"AT?T" + eol + b"AT*SENDIM,5,2,ack,he\r\no" + eol + b"AT!AL5" + eol
    events = codec.receive_data(data)
    assert events == [Command("?T"), Command("*SENDIM", "", ("5", "2", "ack"), b"he\r\no"), Command("!AL", "5")]
    assert feed_bytewise(ModemCodec(), data) == events


def test_modem_escape_in_command_mode_is_wrong_format_and_data_mode_works():
    codec = ModemCodec()
    assert codec.receive_data(b"+++AT?T\r") == [BadCommand("WRONG FORMAT", "+++AT in command mode")]
    assert codec.receive_data(b"hello\r") == [BadCommand("WRONG FORMAT", "hello")]
    assert codec.receive_data(b"ATO\r")[0].name == "O" and codec.data_mode
    events = codec.receive_data(b"burst bytes+++AT?T\r+++ATC\r")
    assert events == [Data(b"burst bytes"), Command("?T", escaped=True), Command("C", escaped=True)]
    assert not codec.data_mode


def test_modem_replies_and_notifications_in_both_modes():
    codec = ModemCodec()
    assert codec.reply(Command("?T"), "1500") == b"1500\r\n"
    text, payload = ModemCodec.recvim(1, 2, b"a\r\n", True, 900, -40, 120, 0.0)
    assert codec.notify_line(text, payload) == b"RECVIM,3,1,2,ack,900,-40,120,0.00,a\r\n\r\n"
    codec.data_mode = True
    assert codec.reply(Command("?T", escaped=True), "1500") == b"+++AT?T:4:1500\r\n"
    assert codec.notify_line("DELIVEREDIM,2") == b"+++AT:13:DELIVEREDIM,2\r\n"


def test_host_and_modem_codecs_understand_each_other():
    host, modem = HostCodec(), ModemCodec()
    command = modem.receive_data(host.command("*SENDIM", payload=NASTY, fields=(9, "ack")))[0]
    assert command.payload == NASTY and command.fields[1:] == ("9", "ack")
    assert host.receive_data(modem.reply(command, "OK")) == [Reply("*SENDIM", "OK")]
    text, payload = ModemCodec.recvim(3, 9, NASTY, False, 1, -2, 3, 0.0)
    [note] = host.receive_data(modem.notify_line(text, payload))
    assert note.payload == NASTY and note.field(1) == "3"


# -- S100 -----------------------------------------------------------------------------------------------


def test_s100_pieces_and_hunting():
    simple = packet_class("simple:20")
    real = simple.encode(bytes(range(0x41, 0x52)))
    assert pieces(real, rtscts=True) == [real + b"\r\n"]
    long = packet_class("vl2b").encode(b"x" * 100)
    cut = pieces(long, rtscts=False)
    assert [len(p) for p in cut] == [45, 45, 17] and b"".join(cut) == long + b"\r\n"
    # the CR LF is never written after a pacing sleep on its own, behind a short piece
    for size in range(0, 140):
        cut = pieces(bytes(size), rtscts=False)
        assert b"".join(cut) == bytes(size) + b"\r\n" and all(len(p) == 45 for p in cut[:-1])
        assert cut[-1].endswith(b"\n") and 0 < len(cut[-1]) <= 45
    hunter = FrameHunter(simple)
    events = hunter.receive_data(b"\r\n+++NOTICE\r\njunk" + real[:7])
    events += hunter.receive_data(real[7:] + b"\r\n")
    # CR and LF between frames are reported (an emulated S100 passes them on; the driver ignores them)
    assert events[0] == Skipped(2, "terminator", b"\r\n") and events[-1] == Skipped(2, "terminator", b"\r\n")
    events = [e for e in events if not (isinstance(e, Skipped) and e.reason == "terminator")]
    assert events[0] == Notice(b"+++NOTICE") and events[1] == Skipped(4, "no preamble", b"junk")
    assert events[2] == Decoded(real, bytes(range(0x41, 0x52)), 0, 255, 255)


def test_s100_hunter_a_preamble_inside_a_notice_does_not_hold_the_frames_behind_it():
    """Found by the fuzz test: the "U" of "EFAULT" is vl1b's preamble with a length of "L" (76), so the
    hunter waited for 76 bytes before ending the notice, holding back three whole frames behind it."""
    wire = wire_class(packet_class("vl1b"))
    frames = [wire.encode(b"\x00")] * 3
    stream = b"+++ATERROR EFAULT\r\nRECVIM," + b"\r\n".join(frames) + b"\r\n"
    hunter = FrameHunter(packet_class("vl1b"))
    found = [e.real for i in range(0, len(stream), 5) for e in hunter.receive_data(stream[i:i + 5])
             if isinstance(e, Decoded)]
    assert found == frames


# -- fuzz ----------------------------------------------------------------------------------------------

_pieces = st.sampled_from([b"RECVIM,", b"RECV,", b"RECVPBM,", b"+++AT", b":", b"\r\n", b"\r", b"\n", b",", b"5",
                           b"12", b"ack", b"OK", b"ERROR EFAULT", b"DELIVEREDIM,2", b"p0,", b"\x00", b"AT*SENDIM,",
                           b"AT*SEND,", b"AT?T", b"+++ATC", b"ATO", b"\x55", b"\x55\x55", b"\xa5\x5a", b"+++"])
_streams = st.lists(st.one_of(_pieces, st.binary(max_size=12)), max_size=40).map(b"".join)


@settings(max_examples=1500, deadline=None)
@given(_streams, st.booleans(), st.integers(1, 7))
def test_fuzz_host_codec(data, data_mode, chunk):
    codec = HostCodec(data_mode=data_mode)
    codec.command("?T")
    for i in range(0, len(data), chunk):
        for event in codec.receive_data(data[i:i + chunk]):
            assert isinstance(event, (Reply, Notification, AsyncError, Data, Unexpected, AtProtocolError))


@settings(max_examples=1500, deadline=None)
@given(_streams, st.integers(1, 7))
def test_fuzz_modem_codec(data, chunk):
    codec = ModemCodec()
    for i in range(0, len(data), chunk):
        for event in codec.receive_data(data[i:i + chunk]):
            assert isinstance(event, (Command, BadCommand, Data))


def test_s100_hunter_does_not_end_a_notice_at_a_crlf_inside_a_frame_still_arriving():
    """Found by the fuzz test below: ``+++AT`` noise, then a frame whose payload holds CR LF, read 5
    bytes at a time.  The notice must not end at that CR LF while the frame is still arriving."""
    packet = packet_class("simple:20")
    wire = wire_class(packet)
    frames = [wire.encode(b"\r\n"), wire.encode(b"\x00"), wire.encode(b"\x00")]
    stream = b"+++AT" + b"\r\n".join(frames) + b"\r\n"
    for chunk in (1, 5, len(stream)):
        hunter = FrameHunter(packet)
        found = []
        for i in range(0, len(stream), chunk):
            found += [e.real for e in hunter.receive_data(stream[i:i + chunk]) if isinstance(e, Decoded)]
        assert found == frames, chunk


@settings(max_examples=1000, deadline=None)
@given(st.sampled_from(["simple:20", "vl1b", "vl2b", "dlf16", "dlf32", "raw"]), _streams, st.data())
def test_fuzz_s100_hunter_finds_every_good_frame_in_noise(name, noise, data):
    packet = packet_class(name)
    wire = wire_class(packet)
    frames = [wire.encode(data.draw(st.binary(min_size=1, max_size=min(40, packet.max_payload)))) for _ in range(3)]
    stream = noise + b"\r\n".join(frames) + b"\r\n"
    hunter = FrameHunter(packet)
    found = []
    for i in range(0, len(stream), 5):
        found += [e.real for e in hunter.receive_data(stream[i:i + 5]) if isinstance(e, Decoded)]
    # noise may contain something frame-like before them, but the three frames all come out in order
    tail = found[-3:]
    assert tail == frames
