"""Frames without a receiver: dccomms applications rarely write the virtual destination
(hello_world_tx leaves it 0), and UWSim-NET without a MAC delivers every frame to every device in
range.  hilgate does the same by default for packet classes that carry no address on air, and with
``addressing: strict`` a frame addressed to nobody is traced and counted instead of vanishing."""

import time

import pytest

from daemon_kit import peer_events, unique
from hilgate.scene import load_scene_text


def scene(a: str, b: str, addressing: str = "", packet: str = "vl2b", mac: str = "none") -> str:
    extra = f", addressing: {addressing}" if addressing else ""
    return f"""\
name: dccomms-tutorial
channels: {{rf: {{speed_mps: 2.25e7}}}}
vehicles:
  v0: {{pose: {{static: [0, 0, 0]}}}}
  v1: {{pose: {{static: [1, 0, 0]}}}}
links:
  {a}: {{vehicle: v0, address: 1, bitrate_bps: 1800, packet: {packet}, mac: {mac}{extra}}}
  {b}: {{vehicle: v1, address: 2, bitrate_bps: 1800, packet: {packet}, mac: {mac}{extra}}}
trace: {{poses_s: 0}}
"""


def test_who_hears_a_frame_follows_the_packet_class_and_the_mac():
    def everyone(**kw):
        spec = load_scene_text(scene("a", "b", **kw)).links["a"]
        return spec.everyone_in_range

    assert everyone() is True                                   # vl2b, no MAC: as UWSim-NET
    assert everyone(addressing="strict") is False
    assert everyone(packet="dlf16") is False                    # the address is in the frame
    assert everyone(mac="{protocol: cs-aloha, max_range_m: 10}") is False                   # a MAC addresses its frames


@pytest.mark.parametrize("addressing", ["", "strict"])
def test_a_dccomms_application_that_leaves_the_destination_at_0(daemon_of, addressing):
    a, b = unique("a"), unique("b")
    daemon = daemon_of(scene(a, b, addressing), [a, b])
    try:
        receiver = daemon.peer(b, "--receive", "3", "--timeout", "60" if not addressing else "3")
        assert next(iter(receiver.stdout.readline, ""))  # its REQ_STATE is out: it is there
        sender = daemon.peer(a, "--send", "3", "--dst", "0", "--size", "20", "--interval", "0.2", "--timeout", "1")
        peer_events(sender, 60)
        frames = [e for e in peer_events(receiver, 60) if e["ev"] == "frame"]
        # strict: a frame is counted when the daemon reads it, which a loaded host may delay past the sender's
        # exit and the receiver's 3 s (the sender's start-up alone can take that long)
        deadline = time.monotonic() + 60
        while addressing and sum(daemon.link_status(a)["drop_causes"].values()) < 3:
            assert time.monotonic() < deadline, daemon.link_status(a)
            time.sleep(0.05)
        status = daemon.link_status(a)
    finally:
        daemon.stop()
        events = daemon.trace_events()
    if not addressing:
        assert [f["payload"].rstrip(".") for f in frames] == [f"{a}#{i:04d}" for i in range(3)]
        assert all(f["dst"] == 0 for f in frames)  # the virtual area is delivered as the application wrote it
        assert not [e for e in events if e.get("cause") == "no_receiver"]
    else:
        assert frames == []
        assert status["drop_causes"] == {"no_receiver": 3}
        assert [e["dst"] for e in events if e.get("cause") == "no_receiver"] == ["addr:0"] * 3
