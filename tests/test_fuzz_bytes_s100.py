"""Every byte value crosses the Seatooth S100 family end to end, both ways (issue 38 item 3).

hilgate's driver → the emulated S100's pty (a serial line at 115 200 baud) → the simulated channel → the
far emulated S100 → the far driver → its application, byte for byte, for ``raw`` links (hilgate's own
framing on the line, ``A5 5A``, length, payload, CRC-16: payloads of 1 to 4096 bytes), with and without
RTS/CTS (without it the driver paces 45-byte pieces at the air bit rate and the far driver joins them);
CR LF, ``+++`` lines and the rest of :data:`bytes_kit.SPECIALS` inside the payloads (an S100 ends a packet
at CR LF: the framing keeps a frame whole).  No outside S100 library exists in Python (dccomms' bridge is
C++): hilgate's driver is at both ends.  One daemon for the module.
"""

import pytest
from hypothesis import example, given

from bytes_kit import crossed, edges, many, payloads, running
from daemon_kit import unique
from hilgate.client import Link

MOST = 4096  # hilgate's frame for raw links on a byte-stream modem (core/packets.py HilgateFrame)
BITRATE = 100_000


def scene(tmp_path, ids):
    lines = []
    for mode, channel, rtscts in (("flow", "c1", "true"), ("paced", "c2", "false")):
        for side, address in (("a", 1), ("b", 2)):
            pty = tmp_path / f"{mode}_{side}"
            line = f"baud: 115200, rtscts: {rtscts}"
            lines.append(f"  {ids[mode, side]}: {{vehicle: v{side}, channel: {channel}, backend: s100, port: {pty}, "
                         f"address: {address}, {line}, bitrate_bps: {BITRATE}, packet: raw, gli: [socket]}}\n")
            lines.append(f"  {ids[mode, side, 'emu']}: {{vehicle: v{side}, channel: {channel}, address: {address}, "
                         f"bitrate_bps: {BITRATE}, packet: raw, gli: [socket], "
                         f"emulate: {{protocol: s100, pty: {pty}, {line}}}}}\n")
    return ("channels: {c1: {speed_mps: 1500}, c2: {speed_mps: 1500}}\n"
            "vehicles:\n  va: {pose: {static: [0, 0, 0]}}\n  vb: {pose: {static: [10, 0, 0]}}\n"
            "links:\n" + "".join(lines))


@pytest.fixture(scope="module")
def ends(tmp_path_factory):
    """Per line, the two drivers' applications: ``{"flow": (a, b), "paced": (a, b)}``."""
    modes = ("flow", "paced")
    ids = {key: unique("s") for key in [(m, s) for m in modes for s in "ab"] + [(m, s, "emu") for m in modes for s in "ab"]}
    tmp = tmp_path_factory.mktemp("ptys")
    with running(tmp_path_factory, scene(tmp, ids), list(ids.values())) as daemon:
        daemon.wait_up(*(ids[m, s] for m in modes for s in "ab"))
        links = {m: (Link.open(ids[m, "a"], runtime_dir=daemon.runtime), Link.open(ids[m, "b"], runtime_dir=daemon.runtime))
                 for m in modes}
        try:
            yield links
        finally:
            for pair in links.values():
                for link in pair:
                    link.close()


@many(12)
@given(payload=payloads(MOST))
@example(payload=edges(MOST)[0]).via("every special")
@example(payload=edges(MOST)[1]).via("4096 bytes")
@example(payload=b"\r\n").via("a CR LF alone")
def test_fuzz_every_byte_crosses_with_flow_control_both_ways(ends, payload):
    a, b = ends["flow"]
    assert crossed(a, b, payload, dst=2) == payload
    assert crossed(b, a, payload, dst=1) == payload


@many(8)
@given(payload=payloads(MOST))
@example(payload=edges(MOST)[1]).via("4096 bytes in 45-byte pieces")
@example(payload=b"+++\r\n").via("a modem notice's shape")
def test_fuzz_every_byte_crosses_in_paced_pieces_both_ways(ends, payload):
    a, b = ends["paced"]
    assert crossed(a, b, payload, dst=2) == payload
    assert crossed(b, a, payload, dst=1) == payload
