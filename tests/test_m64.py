"""The Water Linked Modem-M64: its codec, the emulator driven by Water Linked's own ``wlmodem`` library
(unmodified, installed by the test extra), and hilgate's driver against the emulator.

The library is the independent reference: its ``WlModem`` speaks to the emulated modems over ptys as it
would to real ones (connect, configure, version, payload size, diagnostics, queue, flush, receive), its
``WlUDPSocket`` carries a datagram across, and its framing functions check hilgate's (CRC-8, COBS/R,
padding).  Times are asserted on the model's clock, from the trace, never on the wall clock; the daemon
runs at ``--speed`` so that the modem's one packet a second costs a quarter of a second here.
"""


import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

wlmodem = pytest.importorskip("wlmodem")
from wlmodem import WlModem, WlUDPSocket  # noqa: E402
from wlmodem import transport as wl_transport  # noqa: E402

from daemon_kit import SCENE_HEAD, unique, wait_until  # noqa: E402
from fuzzkit import examples  # noqa: E402
from hilgate.client import Link  # noqa: E402
from hilgate.drivers import m64_codec as codec  # noqa: E402
from hilgate.drivers.m64_codec import (BadChecksum, BadDatagram, Command, Datagram, Deframer, HostCodec,  # noqa: E402
                                       Malformed, ModemCodec, Packet, Refused, Response)

SPEED = 4
AIRTIME = 8 * 8 / 200  # an 8-byte packet at the preset's 200 bit/s
RX_DELAY = 1.1


# -- the codec, without a port -------------------------------------------------------------------------


def test_checksums_are_those_of_the_public_protocol_document():
    # Water Linked's "Modem-M64 serial protocol", its examples section
    assert ModemCodec.response("v", "1", "0", "1") == b"wrv,1,0,1*44\n"
    assert ModemCodec.response("n", "8") == b"wrn,8*ba\n"
    assert ModemCodec.response("s", "a") == b"wrs,a*01\n"
    assert ModemCodec.response("q", "a") == b"wrq,a*d7\n"
    assert ModemCodec.packet(b"HelloTop") == b"wrp,8,HelloTop*bb\n"
    assert ModemCodec.packet(b"HelloSea") == b"wrp,8,HelloSea*58\n"


def test_the_modem_takes_commands_with_or_without_checksum_and_payloads_by_their_length():
    modem = ModemCodec()
    events = modem.receive_data(b"\nwcv\r\nwcs,b,3\nwcq,8,a*\n\r,\x00*z\n" + HostCodec().queue(b"\n\n*12345"))
    assert events == [Command("v"), Command("s", ("b", "3")), Command("q", ("8",), b"a*\n\r,\x00*z"),
                      Command("q", ("8",), b"\n\n*12345", checked=True)]
    assert modem.receive_data(b"wcs,a,3*00\n") == [BadChecksum(b"wcs,a,3*00")]
    assert [type(e) for e in modem.receive_data(b"hello\nwxv\n")] == [Malformed, Malformed]
    # the modem always sends its checksum, its refusals included
    assert ModemCodec.refusal(BadChecksum()) == b"wr!*1e\n" and ModemCodec.refusal(Malformed("x")).startswith(b"wr?*")


def test_a_payload_that_ends_in_cr_is_the_payload_not_a_line_end():
    """``wlmodem`` sends ``wcq,8,<8 bytes>`` and LF, no checksum: a payload whose 8th byte is CR ends in CR LF,
    and that CR is the payload's (it was taken for a CR LF line end: 7 bytes, ``wrq,n``, and the datagram
    lost, about one random WlUDPSocket packet in 256)."""
    modem = ModemCodec()
    assert modem.receive_data(b"wcq,8,1234567\r\n") == [Command("q", ("8",), b"1234567\r")]
    assert modem.receive_data(b"wcq,8,\r\r\r\r\r\r\r\r\r\n") == [Command("q", ("8",), b"\r" * 8)]
    assert modem.receive_data(b"wcv\r\n") == [Command("v")]  # a CR after the sentence is still its line end
    host = HostCodec(with_checksum=False)
    assert host.receive_data(b"wrp,8,1234567\r\r\n") == [Packet(b"1234567\r")]  # CR LF after the payload


def test_the_host_reads_what_wlmodem_reads():
    host = HostCodec()
    assert host.receive_data(ModemCodec.packet(b"\n*\r\n\x00abc") + b"wr?\nwr!\n" + ModemCodec.response("d", "y", "3", "1", "0.0")) == [
        Packet(b"\n*\r\n\x00abc"), Refused("malformed"), Refused("checksum"), Response("d", ("y", "3", "1", "0.0"))]
    # the library's own parser agrees with every sentence the emulated modem sends
    parser = wlmodem.protocol.WlProtocolParser()
    for line in (ModemCodec.response("v", "1", "0", "1"), ModemCodec.packet(b"ab*cdefg"), ModemCodec.response("l", "12")):
        parsed = parser.parse(bytearray(line[:-1]))
        assert parsed.dir == ord("r") and parsed.cmd == line[2]


@settings(max_examples=examples(300), deadline=None)
@given(st.lists(st.one_of(st.binary(max_size=40), st.sampled_from([b"wcq,8,", b"wrp,8,", b"*", b"\n", b"\r\n", b"w"]),
                          st.builds(lambda p: HostCodec().queue(p), st.binary(min_size=8, max_size=8))), max_size=12))
def test_fuzz_m64_codecs_never_fail_and_never_hold_much(chunks):
    modem, host = ModemCodec(), HostCodec()
    for chunk in chunks:
        for event in modem.receive_data(chunk):
            assert isinstance(event, (Command, Malformed, BadChecksum))
        for event in host.receive_data(chunk):
            assert isinstance(event, (Response, Packet, Refused, Malformed, BadChecksum))
    assert len(modem._splitter.buffer) <= codec.MAX_SENTENCE + codec.MAX_PAYLOAD + 8
    assert len(host._splitter.buffer) <= codec.MAX_SENTENCE + codec.MAX_PAYLOAD + 8


@settings(max_examples=examples(200), deadline=None)
@given(st.binary(min_size=1, max_size=120))
def test_fuzz_m64_datagram_framing_is_wlmodems(data):
    framed = codec.frame(data)
    assert framed == bytes(wl_transport.frame(data))
    assert codec.packets(framed) == [bytes(wl_transport.pad_payload(framed[i:i + 8], 8))
                                     for i in range(0, len(framed), 8)]
    assert all(p != bytes(8) for p in codec.packets(framed))  # never the reserved sync packet
    deframer = Deframer()
    assert [e for p in codec.packets(framed) for e in deframer.receive_packet(p)] == [Datagram(data)]


def test_a_lost_packet_damages_its_datagram_which_is_refused_not_delivered():
    data = b"a datagram of several packets, one of which is lost"
    pieces = codec.packets(codec.frame(data))
    deframer = Deframer()
    events = [e for i, p in enumerate(pieces) if i != 2 for e in deframer.receive_packet(p)]
    assert len(events) == 1 and isinstance(events[0], BadDatagram) and events[0].reason in ("crc", "cobs")
    after = [e for p in codec.packets(codec.frame(b"next")) for e in deframer.receive_packet(p)]
    assert after == [Datagram(b"next")]  # the stream recovers at the next frame end


# -- the emulator, driven by wlmodem -------------------------------------------------------------------


def scene(tmp_path, ea, eb, error_b="0", distance=150, extra=""):
    return f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {{static: [{distance}, 0, 0]}}}}
links:
  {ea}: {{vehicle: va, model: m64, address: 1, gli: [socket], emulate: {{protocol: m64, pty: {tmp_path / 'a'}}}}}
  {eb}: {{vehicle: vb, model: m64, address: 2, gli: [socket], error: {{unit: packet, expr: "{error_b}"}},
         emulate: {{protocol: m64, pty: {tmp_path / 'b'}, role: b}}}}
{extra}"""


def open_modems(*paths):
    modems = [WlModem(str(p)) for p in paths]
    for m in modems:
        assert m.connect()
    return modems


def close_modems(*modems):
    for m in modems:
        m._serial.close()


def test_wlmodem_connects_configures_queues_flushes_and_receives_between_two_emulated_m64s(tmp_path, daemon_of):
    ea, eb = unique("ma"), unique("mb")
    daemon = daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    a, b = open_modems(tmp_path / "a", tmp_path / "b")
    assert a.payload_size == 8 and a.cmd_get_version() == [1, 0, 1]
    assert a.cmd_configure("a", 4) and b.cmd_configure("b", 4)
    assert a.request(ord("c")).options == [b"a", b"4"] and b.request(ord("c")).options == [b"b", b"4"]
    assert not a.cmd_configure("c", 4)  # wrs,n (the library checks the channel itself)
    assert a.cmd_get_queue_length() == 0
    assert a.cmd_queue_packet(b"HelloSea") and a.cmd_queue_packet(b"Hi*there")  # '*' as 6th byte: wlmodem's quirk
    assert b.get_data_packet(timeout=30) == b"HelloSea"
    assert b.get_data_packet(timeout=30) == b"Hi*there"
    assert a.cmd_queue_packet(b"1234567\r")  # its CR is the payload's, not a line end (was wrq,n)
    assert b.get_data_packet(timeout=30) == b"1234567\r"
    assert b.cmd_queue_packet(b"HelloTop")
    assert a.get_data_packet(timeout=30) == b"HelloTop"
    for _ in range(3):
        assert a.cmd_queue_packet(b"flushed!")
    assert a.cmd_get_queue_length() >= 1 and a.cmd_flush_queue() and a.cmd_get_queue_length() == 0
    diag_a, diag_b = a.cmd_get_diagnostic(), b.cmd_get_diagnostic()
    assert diag_a["link_up"] and diag_b["link_up"] and diag_b["pkt_cnt"] >= 2 and diag_b["pkt_loss_cnt"] == 0
    with pytest.raises(wlmodem.WlModemGenericError):
        a.cmd_queue_packet(b"too long for a packet")
    close_modems(a, b)
    daemon.stop()
    events = daemon.trace_events()
    tx_a = {e["pkt"]: e["t"] for e in events if e.get("link") == ea and e["ev"] == "tx"}
    tx_b = {e["pkt"]: e["t"] for e in events if e.get("link") == eb and e["ev"] == "tx"}
    rx_b = [e for e in events if e.get("link") == eb and e["ev"] == "rx"]
    rx_a = [e for e in events if e.get("link") == ea and e["ev"] == "rx"]
    # role A sends every second of model time; B answers 50 ms after A's packet has reached it
    slots = sorted(tx_a.values())
    assert [round(t2 - t1, 9) for t1, t2 in zip(slots, slots[1:])] == [1.0] * (len(slots) - 1)
    answers = sorted(tx_b.values())
    assert all(any(round(tb - ta, 9) == round(AIRTIME + 0.1 + 0.05, 9) for ta in slots) for tb in answers)
    # each packet reaches the host after its air time, 150 m at 1500 m/s and the decoding delay
    assert rx_b and all(round(e["t"] - tx_a[e["pkt"]], 9) == round(AIRTIME + 0.1 + RX_DELAY, 9) for e in rx_b)
    assert rx_a and all(round(e["t"] - tx_b[e["pkt"]], 9) == round(AIRTIME + 0.1 + RX_DELAY, 9) for e in rx_a)
    flushed = [e for e in events if e["ev"] == "drop" and e.get("link") == ea]
    assert flushed and {e["cause"] for e in flushed} == {"flushed"}


def test_a_wlmodem_datagram_crosses_two_emulated_m64s_both_ways(tmp_path, daemon_of):
    ea, eb = unique("ma"), unique("mb")
    daemon = daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    sockets = []
    try:
        a, b = open_modems(tmp_path / "a", tmp_path / "b")
        assert a.cmd_configure("a", 2) and b.cmd_configure("b", 2)
        sa, sb = WlUDPSocket(a), WlUDPSocket(b)
        sockets = [sa, sb]
        message = b"a datagram from the surface, \x00 and \n inside"
        assert sa.send(message)
        assert wait_until(lambda: sb.receive()) == message
        assert sb.send(b"and one from the ROV")
        assert wait_until(lambda: sa.receive()) == b"and one from the ROV"
    finally:
        for s in sockets:
            s.stop()


def test_a_modem_whose_partner_falls_silent_misses_several_packets_and_loses_sync(tmp_path, daemon_of):
    """Water Linked: B "will go back to listen mode if several consecutive packets from the modem with role A
    cannot be decoded (i.e. signal is lost)", and an undecodable packet counts in ``pkt_loss_cnt``.  When A
    moves to another channel nothing more arrives at B: B misses a packet a slot (counted, traced ``missed``)
    until it has missed three, then listens (link ``n``) and counts no more.  B follows A there, the pair is
    in sync again, and B leaves: A, which hears no answers any more, the same.  (Before, nothing that never
    arrived was counted: the figures froze and the link flag only said that nothing came lately.)"""
    ea, eb = unique("ma"), unique("mb")
    daemon = daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    a, b = open_modems(tmp_path / "a", tmp_path / "b")

    def in_sync(modem):
        return wait_until(lambda: (d := modem.cmd_get_diagnostic()) and d["link_up"] and d or None)

    def moved(link, band):
        t = wait_until(lambda: next((e["t"] for e in daemon.trace_so_far()[::-1] if e["ev"] == "band"
                                     and e["link"] == link and e["band_khz"] == band), None))
        wait_until(lambda: any(e["t"] > t + 8 for e in daemon.trace_so_far()) or None)  # the model's 8 s
        return t

    assert a.cmd_configure("a", 3) and b.cmd_configure("b", 3)
    assert in_sync(b)["pkt_loss_cnt"] == 0 and in_sync(a)["pkt_loss_cnt"] == 0
    assert a.cmd_configure("a", 6)  # B is left alone on channel 3 (A starts a new pairing: it counts nothing)
    a_moved = moved(ea, [187.0, 218.0])
    silent_b = b.cmd_get_diagnostic()
    assert not silent_b["link_up"] and silent_b["pkt_loss_cnt"] == 3
    assert b.cmd_configure("b", 6)  # B follows: in sync again
    assert in_sync(a)["pkt_loss_cnt"] == 0 and in_sync(b)
    assert b.cmd_configure("b", 2)  # and leaves: A is left alone
    b_moved = moved(eb, [62.25, 93.75])
    silent_a = a.cmd_get_diagnostic()
    close_modems(a, b)
    daemon.stop()
    assert not silent_a["link_up"] and silent_a["pkt_loss_cnt"] == 3
    events = daemon.trace_events()
    for link, since in ((eb, a_moved), (ea, b_moved)):
        missed = [e for e in events if e.get("link") == link and e["ev"] == "err" and e["cause"] == "missed"]
        assert len(missed) == 3 and [e.get("sync") for e in missed] == [None, None, "lost"]
        times = [e["t"] for e in missed]
        assert [round(t2 - t1, 9) for t1, t2 in zip(times, times[1:])] == [1.0, 1.0]  # one a slot
        assert times[0] > since


def test_packets_the_model_loses_show_in_wcd_and_in_the_trace_and_channels_do_not_meet(tmp_path, daemon_of):
    ea, eb = unique("ma"), unique("mb")
    # B's receiver loses half of what it hears (its error model); A hears B perfectly
    daemon = daemon_of(scene(tmp_path, ea, eb, error_b="0.5"), [ea, eb], "--speed", str(SPEED))
    a, b = open_modems(tmp_path / "a", tmp_path / "b")
    assert a.cmd_configure("a", 3) and b.cmd_configure("b", 3)
    wait_until(lambda: (d := b.cmd_get_diagnostic()) and d["pkt_loss_cnt"] >= 2 and d["pkt_cnt"] >= 2 or None)
    # A moves to channel 5: B hears nothing of it any more (another band), so its figures stop once
    # what was on its way has arrived and it has missed what it then expected (the model's time, read
    # from the live trace: 8 s after the move)
    assert a.cmd_configure("a", 5)
    moved = wait_until(lambda: next((e["t"] for e in daemon.trace_so_far() if e["ev"] == "band"
                                     and e["link"] == ea and e["band_khz"] == [156.0, 187.0]), None))
    wait_until(lambda: any(e["t"] > moved + 8 for e in daemon.trace_so_far()) or None)  # B has missed its three
    final = b.cmd_get_diagnostic()
    close_modems(a, b)
    daemon.stop()
    events = daemon.trace_events()
    heard = [e for e in events if e.get("link") == eb and e.get("src") == ea and e["ev"] in ("rx", "err")]
    lost = [e for e in heard if e["ev"] == "err"]
    assert lost and {e["cause"] for e in lost} <= {"prop", "col"}
    # B counts every packet from its A that reached it, good or lost: the model's own lines; and, in sync
    # when A moved, those it then missed until three in a row were undecodable (fewer when the last ones
    # before the move were lost already; none when it was listening)
    missed = [e for e in events if e.get("link") == eb and e["ev"] == "err" and e["cause"] == "missed"]
    assert len(missed) <= 3 and all(e["t"] > moved for e in missed)
    assert [e.get("sync") for e in missed[-1:]] in ([], ["lost"])
    assert final["pkt_loss_cnt"] == len(lost) + len(missed)
    assert final["pkt_cnt"] == len(heard) - len(lost)
    assert not [e for e in heard if e["t"] > moved + 2.0]  # nothing from channel 5 reached channel 3


# -- hilgate's driver against the emulator -------------------------------------------------------------


def driver_scene(tmp_path, da, ea, eb, packet, db=None):
    pa, pb = tmp_path / "a", tmp_path / "b"
    far = (f"  {db}: {{vehicle: vb, backend: m64, port: {pb}, role: b, modem_channel: 2, address: 2, packet: {packet},"
           f" gli: [socket], diagnostic_s: 1}}\n") if db else ""
    return f"""\
{SCENE_HEAD}links:
  {da}: {{vehicle: va, backend: m64, port: {pa}, role: a, modem_channel: 2, address: 1, packet: {packet}, gli: [socket],
         diagnostic_s: 2}}
{far}  {ea}: {{vehicle: va, model: m64, address: 1, gli: [socket], emulate: {{protocol: m64, pty: {pa}}}}}
  {eb}: {{vehicle: vb, model: m64, address: 2, gli: [socket], emulate: {{protocol: m64, pty: {pb}}}}}
"""


def test_hilgate_drivers_carry_frames_application_to_application_through_emulated_m64s(tmp_path, daemon_of, busy_host):
    da, db, ea, eb = unique("da"), unique("db"), unique("ea"), unique("eb")
    daemon = daemon_of(driver_scene(tmp_path, da, ea, eb, "vl2b", db), [da, db, ea, eb], "--speed", str(SPEED))
    daemon.wait_up(da, db)
    with Link.open(da, runtime_dir=daemon.runtime) as la, Link.open(db, runtime_dir=daemon.runtime) as lb:
        la.send(b"hello, \x00\n* m64", dst=2)
        message = lb.recv(timeout=60)
        assert message is not None and message.data == b"hello, \x00\n* m64"
        lb.send(b"back", dst=1)
        message = la.recv(timeout=60)
        assert message is not None and message.data == b"back"

    def reports():
        return [e for e in daemon.trace_so_far() if e["ev"] == "modem_stats" and e["link"] == db]

    # the far modem's figures as it gives them after the exchange (asked every second), not before it
    before = len(reports())
    wait_until(lambda: len(reports()) > before)
    daemon.stop()
    events = daemon.trace_events()
    # the frame went as one WlUDPSocket datagram in 8-byte packets, one per slot of A, each reaching the
    # far emulated modem after exactly air time + 150 m + decoding
    real = 1 + 2 + len(b"hello, \x00\n* m64") + 2  # vl2b on air: preamble, length, payload, CRC-16
    data_packets = codec.packets(codec.frame(b"\x00" * real))
    tx_a = {e["pkt"]: e["t"] for e in events if e.get("link") == ea and e["ev"] == "tx"}
    rx_b = [e for e in events if e.get("link") == eb and e["ev"] == "rx"]
    assert all(round(e["t"] - tx_a[e["pkt"]], 9) == round(AIRTIME + 0.1 + RX_DELAY, 9) for e in rx_b)
    assert [e["size"] for e in events if e.get("link") == da and e["ev"] == "tx"] == [real]
    assert [e["size"] for e in events if e.get("link") == db and e["ev"] == "rx"] == [real]
    assert len(data_packets) == 3
    stats = [e for e in events if e["ev"] == "modem_stats" and e["link"] == db]
    assert stats and stats[-1]["link_up"] and stats[-1]["pkt_loss_cnt"] == 0
    assert not [e for e in events if e["ev"] in ("drop", "err") and e.get("link") in (da, db)]


def test_a_wlmodem_datagram_application_and_a_dccomms_application_understand_each_other(tmp_path, daemon_of):
    """hilgate's driver on one modem, Water Linked's WlUDPSocket on the other: raw frames are datagrams."""
    da, ea, eb = unique("da"), unique("ea"), unique("eb")
    daemon = daemon_of(driver_scene(tmp_path, da, ea, eb, "raw"), [da, ea, eb], "--speed", str(SPEED))
    sockets = []
    try:
        daemon.wait_up(da)
        (b,) = open_modems(tmp_path / "b")
        assert b.cmd_configure("b", 2)
        sb = WlUDPSocket(b)
        sockets.append(sb)
        with Link.open(da, runtime_dir=daemon.runtime) as la:
            la.send(b"from a dccomms application", dst=2)
            assert wait_until(lambda: sb.receive()) == b"from a dccomms application"
            assert sb.send(b"from a wlmodem application")
            message = la.recv(timeout=60)
            assert message is not None and message.data == b"from a wlmodem application"
    finally:
        for s in sockets:
            s.stop()


def test_emulated_m64s_are_on_their_power_on_channel_before_any_wcs(tmp_path, daemon_of):
    """Two pairs powered on channels 2 and 4 (``emulate: {channel}``), their roles set there too, no host
    sending ``wcs``: each pair hears only itself.  The power-on channel never reached the simulation (the
    emulator tuned before its link had a backend): both A's transmit at the same instants, and every packet
    collided at both B's (found by tests/test_fuzz_bytes_m64.py)."""
    ids = {(pair, role): unique("m") for pair in (2, 4) for role in "ab"}
    links = "".join(
        f"  {ids[channel, role]}: {{vehicle: {'va' if role == 'a' else 'vb'}, model: m64, address: {channel + (role == 'b')},"
        f" gli: [socket], emulate: {{protocol: m64, pty: {tmp_path / f'{channel}{role}'}, role: {role}, channel: {channel}}}}}\n"
        for channel in (2, 4) for role in "ab")
    daemon = daemon_of(f"channels: {{ac: {{speed_mps: 1500}}}}\nvehicles:\n  va: {{pose: {{static: [0, 0, 0]}}}}\n"
                       f"  vb: {{pose: {{static: [150, 0, 0]}}}}\nlinks:\n{links}", list(ids.values()), "--speed", str(SPEED))
    b2, b4 = open_modems(tmp_path / "2b", tmp_path / "4b")
    for b in (b2, b4):
        figures = wait_until(lambda: (d := b.cmd_get_diagnostic()) and d["pkt_cnt"] >= 3 and d or None)
        assert figures["link_up"] and figures["pkt_loss_cnt"] == 0
    close_modems(b2, b4)
    daemon.stop()
    bands = {e["link"]: e["band_khz"] for e in daemon.trace_events() if e["ev"] == "band"}
    assert bands == {ids[2, "a"]: [62.25, 93.75], ids[2, "b"]: [62.25, 93.75],
                     ids[4, "a"]: [125.0, 156.0], ids[4, "b"]: [125.0, 156.0]}
    assert not [e for e in daemon.trace_events() if e["ev"] == "err"]
