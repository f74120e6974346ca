"""The receiving side's bridge (hilgate.drivers.bridge), without a port: what a simulated link's applications
get of an emulated modem's bytes (issue 24 item 5)."""

from hypothesis import given, settings
from hypothesis import strategies as st

from fuzzkit import examples
from hilgate.core.backend import AppFrame
from hilgate.core.packets import BROADCAST, Raw, packet_class
from hilgate.drivers.bridge import Loss, ReceivingBridge, from_emulator
from hilgate.drivers.s100_codec import wire_class

VL2B = packet_class("vl2b")


def piece(data: bytes, src: int = 1) -> AppFrame:
    """What an emulated S100 puts on air for bytes that are no whole frame (s100_emulator.S100Emulator._send_raw)."""
    frame = AppFrame(data, data, Raw(), 0, src, BROADCAST, 0.5)
    frame.meta = {"s100": "raw"}
    return frame


def message(data: bytes, kind: str = "im") -> AppFrame:
    """What an emulated EvoLogics modem sends for an AT*SENDIM (evologics_emulator.EvologicsEmulator._send)."""
    frame = AppFrame(data, data, Raw(), 0, 1, 2, 0.5)
    frame.meta = {"kind": kind, "ack": False}
    return frame


def cut(data: bytes, size: int = 45) -> list[bytes]:
    return [data[i:i + size] for i in range(0, len(data), size)]


def test_only_an_emulated_modems_bytes_go_through_the_bridge():
    assert from_emulator(piece(b"x")) and from_emulator(message(b"x"))
    assert not from_emulator(AppFrame(b"r", b"p", VL2B, 0, 1, 2))  # a GLI application's frame


def test_s100_pieces_make_whole_frames_per_sender_and_what_makes_none_is_counted():
    bridge = ReceivingBridge(VL2B)
    one, two = VL2B.encode(b"a" * 95), VL2B.encode(b"b" * 95)
    got, losses = [], []
    for a, b in zip(cut(one + b"\r\n"), cut(two + b"\r\n")):  # two senders, pieces interleaved on the channel
        for frame in (piece(a, src=1), piece(b, src=3)):
            frames, lost = bridge.take(frame)
            got += frames
            losses += lost
    assert [(f.payload, f.src, f.real, f.packet.name) for f in got] == [(b"a" * 95, 1, one, "vl2b"),
                                                                        (b"b" * 95, 3, two, "vl2b")]
    assert losses == []
    # a piece lost on air: the bytes before the next good frame are counted when it shows they are no frame
    pieces = cut(one + b"\r\n")
    frames, lost = [], []
    for data in [pieces[0], pieces[2], *cut(two + b"\r\n")]:
        f, l = bridge.take(piece(data))
        frames += f
        lost += l
    assert [f.payload for f in frames] == [b"b" * 95]
    assert sum(loss.size for loss in lost) == len(pieces[0]) + len(pieces[2])  # every byte, its CR LF too
    # a modem notice and line noise: counted, with why
    frames, lost = bridge.take(piece(b"+++NOTICE\r\n"))
    assert frames == [] and lost == [Loss(11, "notice")]
    # what is held when the link closes will never be a frame
    bridge.take(piece(one[:30], src=9))
    assert bridge.flush() == [Loss(30, "incomplete")] and bridge.hunters == {}


def test_an_evologics_message_is_one_frame_of_the_links_class():
    bridge = ReceivingBridge(VL2B)
    good = VL2B.encode(b"hello, \r\n+++AT")
    frames, lost = bridge.take(message(good))
    assert [(f.payload, f.src, f.dst, f.t0) for f in frames] == [(b"hello, \r\n+++AT", 1, 2, 0.5)] and lost == []
    bad = bytearray(good)
    bad[5] ^= 1
    assert bridge.take(message(bytes(bad))) == ([], [Loss(len(bad), "crc")])
    assert bridge.take(message(b"IMC bytes of LSTS DUNE")) == ([], [Loss(22, "preamble")])
    # a raw link takes the message as it is, as the driver on a raw link does
    raw = ReceivingBridge(Raw())
    frame = message(b"anything")
    assert raw.take(frame) == ([frame], [])


@settings(max_examples=examples(200), deadline=None)
@given(st.lists(st.binary(max_size=120), min_size=1, max_size=5), st.integers(1, 60),
       st.sampled_from(["vl2b", "vl1b", "dlf16", "simple:30", "raw"]))
def test_fuzz_frames_cut_anywhere_come_out_whole(payloads, size, name):
    packet = packet_class(name)
    payloads = [p[:packet.max_payload] for p in payloads]
    wire = wire_class(packet)  # (a raw link's S100 carries hilgate's own frames)
    stream = b"".join(wire.encode(p, src=1, dst=2) + b"\r\n" for p in payloads)
    bridge = ReceivingBridge(packet)
    frames, lost = [], []
    for data in cut(stream, size):
        f, l = bridge.take(piece(data))
        frames += f
        lost += l
    expected = [packet.parse_real(wire.encode(p, src=1, dst=2))[1] if name != "raw" else p for p in payloads]
    assert [f.payload for f in frames] == expected and lost == []
    assert bridge.flush() == []
