"""Every byte value crosses the EvoLogics family end to end, both ways (issue 38 item 3).

hilgate's driver → AT*SENDIM (or AT*SEND) on the emulated S2C's pty → the simulated channel → the far
emulated S2C's RECVIM (RECV) → the far driver → its application, byte for byte: payloads of 1 to 64 bytes
as instant messages and of 1 to 1024 as bursts, with CR, LF, NUL, ``+++AT`` lines and the rest of
:data:`bytes_kit.SPECIALS` among them (no outside library speaks AT in Python: DUNE's task was checked by
hand, docs/dune-hand-check.md).  One daemon for the module; the links are fast (200 kbit/s, 10 m) so that
the examples cost the model little time.
"""

import pytest
from hypothesis import example, given

from bytes_kit import crossed, edges, many, payloads, running
from daemon_kit import unique
from hilgate.client import Link

IM, BURST = 64, 1024


def scene(tmp_path, ids):
    lines = []
    for mode, channel, im in (("im", "c1", "true"), ("burst", "c2", "false")):
        for side, address, x in (("a", 1, 0), ("b", 2, 10)):
            pty = tmp_path / f"{mode}_{side}"
            lines.append(f"  {ids[mode, side]}: {{vehicle: v{side}, channel: {channel}, backend: evologics, port: {pty}, "
                         f"address: {address}, "
                         f"im: {im}, packet: raw, gli: [socket]}}\n")
            lines.append(f"  {ids[mode, side, 'emu']}: {{vehicle: v{side}, channel: {channel}, address: {address}, "
                         f"bitrate_bps: 200000, packet: raw, gli: [socket], "
                         f"emulate: {{protocol: evologics, pty: {pty}}}}}\n")
    return ("channels: {c1: {speed_mps: 1500}, c2: {speed_mps: 1500}}\n"
            "vehicles:\n  va: {pose: {static: [0, 0, 0]}}\n  vb: {pose: {static: [10, 0, 0]}}\n"
            "links:\n" + "".join(lines))


@pytest.fixture(scope="module")
def ends(tmp_path_factory):
    """Per mode, the two drivers' applications: ``{"im": (a, b), "burst": (a, b)}``."""
    ids = {key: unique("e") for key in [(m, s) for m in ("im", "burst") for s in "ab"] +
           [(m, s, "emu") for m in ("im", "burst") for s in "ab"]}
    tmp = tmp_path_factory.mktemp("ptys")
    with running(tmp_path_factory, scene(tmp, ids), list(ids.values())) as daemon:
        daemon.wait_up(*(ids[m, s] for m in ("im", "burst") for s in "ab"))
        links = {m: (Link.open(ids[m, "a"], runtime_dir=daemon.runtime), Link.open(ids[m, "b"], runtime_dir=daemon.runtime))
                 for m in ("im", "burst")}
        try:
            yield links
        finally:
            for pair in links.values():
                for link in pair:
                    link.close()


@many(15)
@given(payload=payloads(IM))
@example(payload=edges(IM)[0]).via("every special")
@example(payload=edges(IM)[1]).via("64 bytes")
@example(payload=edges(IM)[2]).via("a lone CR")
def test_fuzz_every_byte_crosses_as_an_instant_message_both_ways(ends, payload):
    a, b = ends["im"]
    assert crossed(a, b, payload, dst=2) == payload
    assert crossed(b, a, payload, dst=1) == payload


@many(8)
@given(payload=payloads(BURST))
@example(payload=edges(BURST)[1]).via("1024 bytes")
@example(payload=b"+++ATC\r\n").via("an escape line")
def test_fuzz_every_byte_crosses_as_a_burst_both_ways(ends, payload):
    a, b = ends["burst"]
    assert crossed(a, b, payload, dst=2) == payload
    assert crossed(b, a, payload, dst=1) == payload
