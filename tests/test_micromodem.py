"""The WHOI Micro-Modem: its codec, the emulator driven by WHOI's own ``acomms`` library (unmodified,
installed by the test extra, run in a process of its own: tests/peers/acomms_peer.py), and hilgate's
driver against the emulator.

``acomms``' ``Micromodem`` connects (``$CCCFQ,SRC``), sends multi-frame packets at two PSK rates and at
rate 0, an acknowledged packet and a ping; the receiving modem's packet, its ``$CACST`` and the ping's
travel time are checked against the model: the packet's time on the channel is the rate's air time plus
150 m at 1500 m/s, exactly, in the trace.  Times are the model's, never the wall clock's.
"""

import json
import math
import re
import subprocess
import sys
import time

import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("acomms")

from daemon_kit import SCENE_HEAD, HERE, unique  # noqa: E402
from fuzzkit import examples  # noqa: E402
from hilgate.client import Link  # noqa: E402
from hilgate.drivers.micromodem_codec import (RATES, BadSentence, CycleStats, HostCodec, ModemCodec,  # noqa: E402
                                              Sentence, checksum, cst, sentence)

SPEED = 4
PEER = f"{HERE}/peers/acomms_peer.py"


# -- the codec, without a port -------------------------------------------------------------------------


def test_sentences_carry_the_nmea_checksum_acomms_computes():
    from acomms.micromodem import Message, nmeaChecksum
    for kind, fields in (("CACYC", (0, 1, 2, 1, 0, 3)), ("CARXD", (1, 2, 0, 1, "48454C4C4F")), ("CAMPR", (2, 1, "0.1000"))):
        line = sentence(kind, *fields)
        body = line[1:line.index(b"*")].decode()
        assert checksum(body) == nmeaChecksum(body)
        parsed = Message(line.decode())  # raises on a bad checksum
        assert parsed["type"] == kind and parsed["params"] == [str(f) for f in fields]


def test_the_modem_side_takes_host_sentences_with_or_without_checksum():
    modem = ModemCodec()
    events = modem.receive_data(b"$CCCFQ,SRC\r\n" + sentence("CCCYC", 0, 1, 2, 1, 0, 3) + b"$CCCYC,0*00\r\nnoise\n$CATXF\n")
    assert events == [Sentence("CCCFQ", ("SRC",)), Sentence("CCCYC", ("0", "1", "2", "1", "0", "3"), True),
                      BadSentence("checksum", b"$CCCYC,0*00"), BadSentence("no sentence", b"noise"),
                      BadSentence("talker", b"$CATXF")]
    assert HostCodec().receive_data(sentence("CAACK", 1, 2, 1, 1)) == [Sentence("CAACK", ("1", "2", "1", "1"), True)]


@settings(max_examples=examples(300), deadline=None)
@given(st.lists(st.one_of(st.binary(max_size=80), st.sampled_from([b"$", b"*", b"\r\n", b"\n", b"$CCCYC,"])), max_size=15))
def test_fuzz_micromodem_codecs_never_fail_and_hold_at_most_a_line(chunks):
    modem, host = ModemCodec(), HostCodec()
    for chunk in chunks:
        for codec in (modem, host):
            for event in codec.receive_data(chunk):
                assert isinstance(event, (Sentence, BadSentence))
            assert len(codec.buffer) <= 1024 + 80


def test_rates_are_the_interface_guides_frames():
    from acomms.messageparams import Rates
    for number, rate in RATES.items():
        assert (rate.frames, rate.frame_bytes) == (Rates[number].numframes, Rates[number].framesize)


# -- the emulator, driven by acomms ----------------------------------------------------------------------


def scene(tmp_path, ea, eb, error_b="0"):
    return f"""\
{SCENE_HEAD}links:
  {ea}: {{vehicle: va, model: micromodem, address: 1, gli: [socket], emulate: {{protocol: micromodem, pty: {tmp_path / 'a'}}}}}
  {eb}: {{vehicle: vb, model: micromodem, address: 2, gli: [socket], error: {{unit: packet, expr: "{error_b}"}},
         emulate: {{protocol: micromodem, pty: {tmp_path / 'b'}}}}}
"""


def run_peer(tmp_path, scenario, timeout=240):
    result = subprocess.run([sys.executable, PEER, scenario, str(tmp_path / "a"), str(tmp_path / "b"),
                             str(tmp_path / "acomms_logs")], capture_output=True, text=True, timeout=timeout)
    assert result.returncode == 0, result.stderr
    return [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]


def test_acomms_sends_packets_at_two_rates_an_acknowledged_one_and_a_ping_through_emulated_micromodems(tmp_path, daemon_of):
    ea, eb = unique("ma"), unique("mb")
    daemon = daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    results = run_peer(tmp_path, "exchange")
    daemon.stop()
    assert results[0] == {"event": "ids", "a": 1, "b": 2}  # $CCCFQ,SRC -> $CACFG,SRC,<the link's address>
    packets = [r for r in results if r["event"] == "packet"]
    rate1 = b"three frames at rate one: " * 7
    assert [bytes.fromhex(f) for f in packets[0]["frames"]] == [rate1[:64], rate1[64:128], rate1[128:182]]
    rate5 = bytes(range(256)) * 3 + b"tail"
    assert [bytes.fromhex(f) for f in packets[1]["frames"]] == [rate5[:256], rate5[256:512], rate5[512:768], b"tail"]
    rssi = round(-20 - 20 * math.log10(150) - 0.15)  # hilgate.models.link_budget at 150 m
    for packet, rate, count in ((packets[0], 1, 3), (packets[1], 5, 4)):
        assert (packet["src"], packet["dest"]) == (1, 2)
        # on the modem's scales: 185 dB re 1 uPa at 1 m less the loss, 105 dB of noise; PSK: no DQF (-1)
        assert packet["cst"] == {"mode": 0, "rate_num": rate, "num_frames": count, "bad_frames_num": 0,
                                 "mfd_pow": rssi + 100, "snr_in": float(rssi + 100), "dqf": -1, "src": 1, "dest": 2}
    assert bytes.fromhex(packets[2]["frames"][0]) == b"FH-FSK, rate 0"
    acked = next(r for r in results if r["event"] == "acked")
    assert acked["acks"] == [[1, 2, 1, True], [1, 2, 2, True]]
    ping = next(r for r in results if r["event"] == "ping")
    assert ping["owtt"] == 0.1  # 150 m at 1500 m/s, measured by the model from the round trip
    assert results[-1] == {"event": "done", "a": "Idle", "b": "Idle"}  # every cycle finished
    events = daemon.trace_events()
    tx = {e["pkt"]: e for e in events if e.get("link") == ea and e["ev"] == "tx" and "kind" not in e}
    rx = [e for e in events if e.get("link") == eb and e["ev"] == "rx" and e["pkt"] in tx]
    # on the channel each packet takes its rate's air time (whole frames) and 0.1 s of propagation
    sizes = {e["size"]: round(e["t"] - tx[e["pkt"]]["t"], 9) for e in rx}
    # (WHOI's own names for the rates, libumutil.h: rate 1 250 bit/s, rate 2 500, rate 5 5300)
    assert sizes[3 * 64] == round(0.3 + 3 * 64 * 8 / 250 + 0.1, 9)  # rate 1, 3 frames (and rate 2: 500 bit/s)
    assert sizes[4 * 256] == round(0.3 + 4 * 256 * 8 / 5300 + 0.1, 9)  # rate 5, 4 frames
    assert sizes[32] == round(32 * 8 / 80 + 0.1, 9)  # rate 0: FH-FSK, no probe
    acks = [e for e in events if e.get("link") == eb and e["ev"] == "tx" and e.get("kind") == "modem_ack"]
    assert len(acks) == 2  # the acknowledged packet's and the ping's reply, on the channel


CACST_V8 = re.compile(  # version 8, zero-padded and positive where a Micro-Modem 2 prints them so
    r"\$CACST,8,[012],\d{14}\.\d{6},\d\d,\d+,\d+,\d{4},\d{4},\d\d,\d\d,\d\d,\d\d,\d\d,[0-6],\d{3},\d{3},\d,\d,"
    r"\d,\d,\d+,\d+\.\d,\d+\.\d\d,-100,-?\d+\.\d\d,(-01|\d{3}),-?\d+\.\d\d,\d+,\d+,\d+,\d+,-1,-1,00\*[0-9A-F]{2}")


def test_a_cacst_is_formatted_as_a_micromodem_2_prints_it():
    """The public v8 capture's own figures give the capture, byte for byte (its checksum included)."""
    capture = (b"$CACST,8,0,20250606230123.348554,06,32767,45,0102,0123,07,00,00,00,00,1,001,000,0,5,1,0,150,26.0,"
               b"9.48,-100,-6.48,-01,0.01,51,25000,5000,0,-1,-1,00*4A\r\n")
    assert cst(CycleStats(mode=0, toa="20250606230123.348554", toa_mode=6, mfd_peak=32767, mfd_pow=45, mfd_ratio=102,
                          mfd_spl=123, agn=7, rate=1, src=1, dest=0, packet_type=5, num_frames=1, bad_frames=0,
                          snr_rss=150, snr_in=26.0, snr_out=9.48, snr_sym=-100, mse=-6.48, dqf=-1, doppler=0.01,
                          noise=51, carrier=25000, bandwidth=5000)) == capture
    assert CACST_V8.fullmatch(capture.strip().decode())


def test_acomms_waits_for_a_data_packet_as_on_a_real_modem(tmp_path, daemon_of):
    """``Micromodem.wait_for_data_packet()`` waits for ``$CARXP`` (a packet detected), then takes the frames
    and the packet's ``$CACST``; at rate 0 (``fsk=True``) the cycle init's ``$CACST`` first.  The emulator
    printed no ``$CARXP``: the call returned None although the packet arrived.  The sender prints ``$CATXP``
    as each packet goes on air, before its ``$CATXF``; the receiver's ``$CACST`` is a Micro-Modem 2's."""
    ea, eb = unique("ma"), unique("mb")
    daemon = daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    results = run_peer(tmp_path, "wait")
    daemon.stop()
    waited = [(r["rate"], r["data"] and bytes.fromhex(r["data"])) for r in results if r["event"] == "waited"]
    assert waited == [(1, b"waited for, at rate one; " * 7), (0, b"an FSK packet, waited for")]
    sentences = next(r for r in results if r["event"] == "sentences")
    sent = [kind for kind in sentences["a"] if kind in ("CATXP", "CATXF")]
    assert sent == ["CATXP", "CATXF"] * 3  # the rate-1 packet; rate 0's cycle init and its packet
    heard = [kind for kind in sentences["b"] if kind in ("CARXP", "CACYC", "CARXD", "CACST")]
    assert heard == ["CARXP", "CACYC", "CARXD", "CARXD", "CARXD", "CACST",  # rate 1: three frames
                     "CARXP", "CACYC", "CACST", "CARXP", "CARXD", "CACST"]  # rate 0: cycle init, then the packet
    rssi = round(-20 - 20 * math.log10(150) - 0.15)
    spl, snr = 185 + 20 + rssi, rssi + 100  # dB re 1 uPa: the source level less the loss; 105 dB of noise
    for line, rate, dqf, kind in zip(sentences["cst"], (1, 0, 0), ("-01", "240", "240"), ("3", "2", "1")):
        assert CACST_V8.fullmatch(line), line
        fields = line.split("*")[0].split(",")
        assert (fields[14], fields[15], fields[16], fields[18]) == (str(rate), "001", "002", kind)
        assert (fields[6], fields[8], fields[21], fields[26], fields[28]) == (str(snr), f"{spl:04d}", str(spl), dqf, "105")
    assert results[-1] == {"event": "done", "a": "Idle", "b": "Idle"}


def test_a_packet_the_model_loses_shows_in_the_receivers_statistics_and_in_the_trace(tmp_path, daemon_of):
    ea, eb = unique("ma"), unique("mb")
    daemon = daemon_of(scene(tmp_path, ea, eb, error_b="1"), [ea, eb], "--speed", str(SPEED))
    results = run_peer(tmp_path, "lost")
    daemon.stop()
    assert {"event": "cst", "mode": 1, "num_frames": 3, "bad_frames_num": 3} in results
    assert not [r for r in results if r["event"] == "packet"]
    assert {"event": "acks", "count": 0} in results  # no acknowledgement for what never arrived
    assert results[-1] == {"event": "done", "a": "Idle", "b": "Idle"}
    lost = [e for e in daemon.trace_events() if e["ev"] == "err" and e.get("link") == eb]
    assert [(e["src"], e["cause"], e["size"]) for e in lost] == [(ea, "prop", 3 * 64)]


def test_a_host_that_gives_no_data_gets_a_data_timeout_and_the_cycle_ends(tmp_path, daemon_of):
    ea, eb = unique("ma"), unique("mb")
    daemon = daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    port = serial.Serial(str(tmp_path / "a"), 19200, timeout=30)
    port.write(b"$CCCYC,0,1,2,1,0,3\r\n")
    lines = [port.read_until(b"\n") for _ in range(3)]
    assert lines[0] == sentence("CACYC", 0, 1, 2, 1, 0, 3)
    assert lines[1].startswith(b"$CADRQ,") and lines[1].split(b",")[2:6] == [b"1", b"2", b"0", b"64"]
    assert lines[2].startswith(b"$CAERR,") and b",DATA_TIMEOUT,1," in lines[2]
    port.write(b"$CCCYC,0,1,2,9,0,3\r\n$CCXYZ\r\n$CCCYC,0,1,2,1,0,3*00\r\n")  # a bad rate, unknown, bad checksum
    errors = [port.read_until(b"\n") for _ in range(3)]
    assert all(line.startswith(b"$CAERR,") for line in errors), errors
    port.write(b"$CCCYC,0,1,2,1,0,1\r\n")  # the modem is free again: the cycle ended
    assert port.read_until(b"\n") == sentence("CACYC", 0, 1, 2, 1, 0, 1)
    port.close()


def test_the_data_timeout_is_the_hosts_seconds_whatever_the_speed(tmp_path, daemon_of):
    """DTO is 5 s of the host's time (a real modem counts it in its own seconds, the host answers in its
    own): a host that gives its frame 2 s after ``$CADRQ`` is in time although the model runs 4 times
    faster (it was a model-time DTO: 1.25 s of the host's time, and a busy host's frame was refused)."""
    ea, eb = unique("ma"), unique("mb")
    daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    port = serial.Serial(str(tmp_path / "a"), 19200, timeout=30)
    port.write(b"$CCCYC,0,1,2,1,0,1\r\n")
    assert port.read_until(b"\n") == sentence("CACYC", 0, 1, 2, 1, 0, 1)
    assert port.read_until(b"\n").startswith(b"$CADRQ,")
    time.sleep(2.0)  # at least 2 s of the host's time: more than DTO / speed
    port.write(b"$CCTXD,1,2,0," + b"ab" * 8 + b"\r\n")
    assert port.read_until(b"\n") == sentence("CATXD", 1, 2, 0, 8)
    port.close()


# -- hilgate's driver against the emulator -----------------------------------------------------------------


def driver_scene(tmp_path, da, db, ea, eb, rate=1, ack=True, packet="vl2b"):
    pa, pb = tmp_path / "a", tmp_path / "b"
    return f"""\
{SCENE_HEAD}links:
  {da}: {{vehicle: va, backend: micromodem, port: {pa}, address: 1, rate: {rate}, ack: {str(ack).lower()}, packet: {packet},
         gli: [socket]}}
  {db}: {{vehicle: vb, backend: micromodem, port: {pb}, address: 2, rate: {rate}, packet: {packet}, gli: [socket]}}
  {ea}: {{vehicle: va, model: micromodem, address: 1, gli: [socket], emulate: {{protocol: micromodem, pty: {pa}}}}}
  {eb}: {{vehicle: vb, model: micromodem, address: 2, gli: [socket], emulate: {{protocol: micromodem, pty: {pb}}}}}
"""


def test_hilgate_drivers_carry_frames_application_to_application_through_emulated_micromodems(tmp_path, daemon_of, busy_host):
    da, db, ea, eb = unique("da"), unique("db"), unique("ea"), unique("eb")
    daemon = daemon_of(driver_scene(tmp_path, da, db, ea, eb), [da, db, ea, eb], "--speed", str(SPEED))
    daemon.wait_up(da, db)
    sent = [b"short", b"x" * 150]  # one frame; three frames of rate 1 (155 bytes of vl2b on air)
    with Link.open(da, runtime_dir=daemon.runtime) as la, Link.open(db, runtime_dir=daemon.runtime) as lb:
        for payload in sent:
            la.send(payload, dst=2)
            message = lb.recv(timeout=60)
            assert message is not None and message.data == payload and message.src == 1
        lb.send(b"back", dst=1)
        message = la.recv(timeout=60)
        assert message is not None and message.data == b"back" and message.src == 2
        la.send(b"y" * 200, dst=2)  # 205 bytes on air: more than rate 1's 3 x 64
        with pytest.raises(Exception, match="do not fit a rate-1 packet of the Micro-Modem"):
            la.recv(timeout=30)
    deadline = time.monotonic() + 60
    while sum(e["ev"] == "delivered" for e in daemon.trace_so_far() if e.get("link") == da) < 2:
        assert time.monotonic() < deadline, "acknowledgements never traced"
        time.sleep(0.05)
    daemon.stop()
    events = daemon.trace_events()
    assert [(e["size"], e["frames"]) for e in events if e.get("link") == da and e["ev"] == "tx"] == [(10, 1), (155, 3)]
    assert [e["size"] for e in events if e.get("link") == db and e["ev"] == "rx"] == [10, 155]
    stats = [e for e in events if e.get("link") == db and e["ev"] == "modem_stats"]
    assert [(e["mode"], e["rate"], e["frames"], e["bad_frames"]) for e in stats] == [(0, 1, 1, 0), (0, 1, 3, 0)]
    # on the simulated channel each packet took its rate's air time for whole frames plus 0.1 s, exactly
    tx = {e["pkt"]: e["t"] for e in events if e.get("link") == ea and e["ev"] == "tx" and "kind" not in e}
    rx = [e for e in events if e.get("link") == eb and e["ev"] == "rx" and e["pkt"] in tx]
    assert [round(e["t"] - tx[e["pkt"]], 9) for e in rx] == [round(0.3 + n * 64 * 8 / 250 + 0.1, 9) for n in (1, 3)]
    losses = [(e["link"], e["cause"]) for e in events if e["ev"] in ("drop", "err") and e.get("link") in (da, db)]
    assert losses == [(da, "size")]  # the 200-byte frame, refused when the application sent it




def test_every_other_acomms_call_a_modem_answers(tmp_path, daemon_of):
    """API level, configuration (all, set, one), the modem's clock (``set_time``, ``get_time_info``), a hardware
    line, a user minipacket, a ping with its statistics and a test packet: each answered as a modem does
    (before, the clock, the minipacket and the line were ``$CAERR``: ``change_gpio`` raised a TypeError)."""
    ea, eb = unique("ma"), unique("mb")
    daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    results = {r["event"]: r for r in run_peer(tmp_path, "calls")}
    assert results["api"]["level"] == 11
    assert {"SRC", "RXP", "TXP", "CST", "DTO"} <= set(results["config"]["all"])
    assert results["config"]["set"] == ["1", "RXP"] and results["config"]["src"] == {"SRC": "1"}
    time_ = results["time"]
    assert time_["set"] == "2031-05-04T03:02:01+00:00" and time_["timed_out"] == "0"
    assert 0 <= time_["ahead_s"] < 30 and (time_["clock"], time_["pps"]) == ("RTC", "NONE")  # (the host's seconds)
    assert results["gpio"]["value"] == 1
    assert results["minipacket"]["data"] == "1ABC"
    assert results["ping"] == {"event": "ping", "owtt": 0.1, "cst": {"mode": 0, "src": 1, "dest": 2, "packet_type": 2}}
    assert results["test_packet"]["got"] == results["test_packet"]["sent"] and len(results["test_packet"]["got"]) == 2
    assert results["done"] == {"event": "done", "a": "Idle", "b": "Idle"}


def test_the_calls_whose_sentences_are_not_emulated_get_the_modems_refusal(tmp_path, daemon_of):
    """Sweeps, FDP packets and pings, JANUS, statistics requests, hibernation, navigation pings and uplink requests are not emulated (docs/conformance-micromodem.md says each): every such call of ``acomms``
    gets ``$CAERR`` (those that wait for an answer return None at their timeout) and leaves the modem idle."""
    ea, eb = unique("ma"), unique("mb")
    daemon_of(scene(tmp_path, ea, eb), [ea, eb], "--speed", str(SPEED))
    results = run_peer(tmp_path, "refused")
    answers = {r["event"]: r.get("answer") for r in results if r["event"] in ("remus", "narrow")}
    assert answers == {"remus": None, "narrow": None}
    errors = next(r["errors"] for r in results if r["event"] == "refused")
    assert errors == [f"NMEA,1,Unsupported {kind}" for kind in ("CCRSP", "CCTDP", "CCCMD", "CCTJN", "CCSST", "CCHIB",
                                                                "CCPDT", "CCPNT")] + [
        "CCCYC,2,Uplink requests are not emulated"]
    assert results[-1] == {"event": "done", "a": "Idle", "b": "Idle"}


def test_a_cycle_the_link_refuses_ends_with_the_modems_restart_sentence(tmp_path):
    """When the model never puts the packet on air (the link refused it: its FIFO full), the emulated modem
    fails the cycle with ``$CAERR,…,CYCLE,5`` and ``$CAREV`` (the one sentence after which every host
    forgets its cycle) and is free again.  In virtual time, the link reduced to a refusal."""
    from hilgate.core.packets import PacketError
    from hilgate.core.scheduler import VirtualScheduler
    from hilgate.drivers.micromodem_emulator import MicromodemEmulator

    class Loop(VirtualScheduler):
        def add_reader(self, fd, fn):
            pass

        def remove_reader(self, fd):
            pass

    class Refusing:
        id, address, limits = "mm", 1, None

        def send(self, frame):
            raise PacketError("fifo", "the link's FIFO is full")

    class Host:
        out = b""

        def write(self, data):
            Host.out += data

    emulator = MicromodemEmulator(Refusing(), {"pty": str(tmp_path / "mm")}, Loop())
    try:
        host = Host()
        emulator.codecs = {host: ModemCodec()}
        emulator._on_data(host, sentence("CCCYC", 0, 1, 2, 1, 0, 1) + sentence("CCTXD", 1, 2, 0, "41"))
        lines = [line for line in Host.out.split(b"\r\n") if line]
        assert [line.split(b",")[0] for line in lines] == [b"$CACYC", b"$CADRQ", b"$CATXD", b"$CAERR", b"$CAREV"]
        assert b",CYCLE,5,Packet not transmitted" in lines[3] and b",AUV,2.0.0*" in lines[4]
        assert emulator.cycle is None  # free for the next cycle
    finally:
        emulator.close()
