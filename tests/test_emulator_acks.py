"""The emulated EvoLogics modem on the acoustic acknowledgements of the model (issue 13, items 1, 2 and 8):
an independent AT client on each pty, exact model times read from the trace."""

import math

import pytest

from at_pty_client import AtClient
from daemon_kit import Daemon, unique

BITRATE, TX_DELAY, TURN, ACK_BYTES = 1900.0, 0.001, 0.27, 6  # models/evologics-s2cr-7-17.yaml
EXACT = dict(abs=2e-9)  # the trace rounds times to the nanosecond


def two_modems(tmp_path, d, a_extra="", b_extra="", b_pose=None):
    a, b = unique("ea"), unique("eb")
    pa, pb = tmp_path / "evo_a", tmp_path / "evo_b"
    b_pose = b_pose or f"{{static: [{d}, 0, 0]}}"
    text = f"""\
seed: 7
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {b_pose}}}
links:
  {a}: {{vehicle: va, model: evologics-s2cr-7-17, address: 1, emulate: {{protocol: evologics, pty: {pa}}}{a_extra}}}
  {b}: {{vehicle: vb, model: evologics-s2cr-7-17, address: 2, emulate: {{protocol: evologics, pty: {pb}}}{b_extra}}}
"""
    daemon = Daemon(tmp_path, text, [a, b])
    daemon.wait_for("READY=1")
    return daemon, a, b, AtClient(pa), AtClient(pb)


def events_of(events, link, ev):
    return [e for e in events if e.get("link") == link and e["ev"] == ev]


def test_an_ack_im_at_7000_m_is_delivered_when_its_acoustic_ack_comes_back(tmp_path):
    # issue 13 item 2: at 7 000 m (preset range 8 km) the old fixed timer said FAILEDIM at 3.034 s
    d, payload = 7000.0, b"hel,\r\no"
    daemon, a, b, ca, cb = two_modems(tmp_path, d)
    try:
        assert ca.ask(b"AT?RI") == b"3"  # the retries the model uses
        ca.send(b"AT*SENDIM,%d,2,ack,%s" % (len(payload), payload))
        assert ca.expect(b"OK")[0] == b"OK"
        text, body = cb.expect(b"RECVIM")
        assert body == payload
        fields = text.split(b",")
        t_im = len(payload) * 8 / BITRATE
        tau = d / 1500
        assert fields[1:5] == [b"7", b"1", b"2", b"ack"]
        assert int(fields[5]) == round(t_im * 1e6)  # the whole frame's air time
        assert int(fields[6]) == round(-20 - 20 * math.log10(d) - d / 1000)  # RSSI from the distance
        assert int(fields[7]) == round(250 - 200 * d / 8000)  # integrity from the distance
        assert fields[8] == b"0.00"  # neither vehicle moves
        assert ca.expect(b"DELIVEREDIM", timeout=30)[0] == b"DELIVEREDIM,2"
        assert not [line for line in ca.settle(0.2) if line.startswith(b"FAILEDIM")]
        assert ca.ask(b"AT?T") == str(round(tau * 1e6)).encode()  # one way, from the round trip
        ca.close(), cb.close()
        daemon.stop()
        events = daemon.trace_events()
        [enq] = events_of(events, a, "enq")
        [data_tx] = events_of(events, a, "tx")
        [ack_tx] = events_of(events, b, "tx")
        [ack_rx] = events_of(events, a, "rx")
        assert ack_tx.get("kind") == ack_rx.get("kind") == "modem_ack" and ack_rx["pkt"] == ack_tx["pkt"]
        t_ack = ACK_BYTES * 8 / BITRATE
        assert data_tx["t"] == pytest.approx(enq["t"] + TX_DELAY, **EXACT)
        assert ack_tx["t"] == pytest.approx(data_tx["t"] + t_im + tau + TURN, **EXACT)
        # DELIVEREDIM is printed at the end of the ACK's arrival (rx delay 0 in the preset)
        assert ack_rx["t"] == pytest.approx(enq["t"] + TX_DELAY + t_im + tau + TURN + t_ack + tau, **EXACT)
        assert not events_of(events, a, "retx") and not events_of(events, a, "giveup")
    finally:
        daemon.close()


def test_acks_lost_to_the_error_model_give_ri_retries_then_failedim_at_the_model_times(tmp_path):
    d, range_max, payload = 300.0, 1500.0, b"ping"
    # every arrival at a (the ACKs) is lost; b hears the IMs well
    daemon, a, b, ca, cb = two_modems(tmp_path, d, a_extra=f", range_m: [0, {range_max}], error: {{expr: '1'}}",
                                      b_extra=f", range_m: [0, {range_max}]")
    try:
        assert ca.ask(b"AT!RI2") == b"OK" and ca.ask(b"AT?RI") == b"2"
        ca.send(b"AT*SENDIM,4,2,ack,ping")
        assert ca.expect(b"OK")[0] == b"OK"
        assert ca.ask(b"AT?DI") == b"DELIVERING"
        assert ca.expect(b"FAILEDIM", timeout=30)[0] == b"FAILEDIM,2"
        bodies = [cb.expect(b"RECVIM")[1] for _ in range(3)]  # the first send and 2 retries: duplicates
        assert bodies == [payload] * 3
        assert not [line for line in ca.settle(0.2) if line.startswith(b"DELIVEREDIM")]
        ca.close(), cb.close()
        daemon.stop()
        events = daemon.trace_events()
        [enq] = events_of(events, a, "enq")
        t_im, t_ack = len(payload) * 8 / BITRATE, ACK_BYTES * 8 / BITRATE
        wait = 2 * range_max / 1500 + TURN + t_ack + 0.001
        attempt = TX_DELAY + t_im + wait
        t0 = enq["t"]
        data_tx = [e for e in events_of(events, a, "tx") if "kind" not in e]
        assert [e["t"] for e in data_tx] == pytest.approx([t0 + k * attempt + TX_DELAY for k in range(3)], **EXACT)
        assert [e["t"] for e in events_of(events, a, "retx")] == pytest.approx(
            [t0 + k * attempt for k in (1, 2)], **EXACT)
        [giveup] = events_of(events, a, "giveup")
        assert giveup["t"] == pytest.approx(t0 + 3 * attempt, **EXACT)  # FAILEDIM is printed then
        # each ACK went on air from b and was lost at a to the error model, traced with its cause
        assert len([e for e in events_of(events, b, "tx") if e.get("kind") == "modem_ack"]) == 3
        assert [e["cause"] for e in events_of(events, a, "err")] == ["prop"] * 3
    finally:
        daemon.close()


def test_bursts_are_retried_rc_times_and_ims_ri_times_as_the_model_says(tmp_path):
    # issue 24 item 6: DUNE sets !RI0 and !RC3; bursts follow !RC, acknowledged IMs !RI.  Every ACK is lost
    # at a, so each frame is sent 1 + its retries times and then reported failed, at the model's times
    d, range_max = 300.0, 1500.0
    daemon, a, b, ca, cb = two_modems(tmp_path, d, a_extra=f", range_m: [0, {range_max}], error: {{expr: '1'}}",
                                      b_extra=f", range_m: [0, {range_max}]")
    rc, ri = 2, 1
    try:
        assert ca.ask(b"AT!RC%d" % rc) == b"OK" and ca.ask(b"AT!RI%d" % ri) == b"OK"
        ca.send(b"AT*SEND,5,2,burst")
        assert ca.expect(b"OK")[0] == b"OK"
        assert ca.expect(b"FAILED,", timeout=60)[0] == b"FAILED,1,2"
        assert [cb.expect(b"RECV,")[1] for _ in range(rc + 1)] == [b"burst"] * (rc + 1)
        ca.send(b"AT*SENDIM,4,2,ack,ping")
        assert ca.expect(b"OK")[0] == b"OK"
        assert ca.expect(b"FAILEDIM", timeout=60)[0] == b"FAILEDIM,2"
        assert [cb.expect(b"RECVIM")[1] for _ in range(ri + 1)] == [b"ping"] * (ri + 1)
        ca.close(), cb.close()
        daemon.stop()
        events = daemon.trace_events()
        t_ack = ACK_BYTES * 8 / BITRATE
        wait = 2 * range_max / 1500 + TURN + t_ack + 0.001
        for (size, retries), enq in zip(((5, rc), (4, ri)), events_of(events, a, "enq")):
            pkt, t0 = enq["pkt"], enq["t"]
            attempt = TX_DELAY + size * 8 / BITRATE + wait
            sent = [e["t"] for e in events_of(events, a, "tx") if e["pkt"] == pkt]
            assert sent == pytest.approx([t0 + k * attempt + TX_DELAY for k in range(retries + 1)], **EXACT)
            assert [e["t"] for e in events_of(events, a, "retx") if e["pkt"] == pkt] == pytest.approx(
                [t0 + k * attempt for k in range(1, retries + 1)], **EXACT)
            [giveup] = [e for e in events_of(events, a, "giveup") if e["pkt"] == pkt]
            assert giveup["t"] == pytest.approx(t0 + (retries + 1) * attempt, **EXACT)
            assert giveup["attempts"] == retries + 1
    finally:
        daemon.close()


def test_recvim_velocity_is_the_vehicles_radial_speed(tmp_path):
    # b comes towards a at 2 m/s from 600 m: the RECVIM at a says +2.00 m/s, and the distance of the moment
    daemon, a, b, ca, cb = two_modems(
        tmp_path, 0, b_pose="{path: {start: [600, 0, 0], legs: [{to: [0, 0, 0], speed_mps: 2}]}}")
    try:
        cb.send(b"AT*SENDIM,2,1,noack,hi")
        assert cb.expect(b"OK")[0] == b"OK"
        text, body = ca.expect(b"RECVIM")
        fields = text.split(b",")
        assert body == b"hi" and fields[4] == b"noack"
        assert fields[8] == b"2.00"
        assert ca.ask(b"AT?E") == fields[6] and ca.ask(b"AT?I") == fields[7]
        ca.close(), cb.close()
    finally:
        daemon.close()


def usbl_fields(text):
    fields = text.split(b",")
    assert fields[0] == b"USBLLONG" and len(fields) == 17, text
    return [float(x) for x in fields[1:]]


def test_a_usbl_link_prints_fixes_of_the_geometry_and_within_its_sigma(tmp_path, daemon_of):
    a, b, c = unique("ua"), unique("ub"), unique("uc")
    pa, pb, pc = tmp_path / "evo_a", tmp_path / "evo_b", tmp_path / "evo_c"
    sigma_r, sigma_b = 0.5, 2.0
    daemon = daemon_of(f"""\
seed: 5
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  boat: {{pose: {{static: [0, 0, 0]}}}}
  rov: {{pose: {{static: [30, 40, 10]}}}}
links:
  {a}: {{vehicle: boat, model: evologics-s2cr-7-17, range_m: [0, 500], address: 1,
        emulate: {{protocol: evologics, pty: {pa}}}, usbl: {{orientation_deg: [0, 0, 90]}}}}
  {c}: {{vehicle: boat, model: evologics-s2cr-7-17, range_m: [0, 500], address: 3, rx_channel: ac, tx_channel: ac,
        emulate: {{protocol: evologics, pty: {pc}}},
        usbl: {{bearing_sigma_deg: {sigma_b}, range_sigma_m: {sigma_r}}}}}
  {b}: {{vehicle: rov, model: evologics-s2cr-7-17, range_m: [0, 500], address: 2,
        emulate: {{protocol: evologics, pty: {pb}}}}}
""", [a, b, c])
    ca, cb, cc = AtClient(pa), AtClient(pb), AtClient(pc)
    cb.send(b"AT*SENDIM,2,1,noack,hi")  # before @ZU1: no fix
    assert cb.expect(b"OK")[0] == b"OK"
    ca.expect(b"RECVIM")
    assert not [line for line in ca.settle(0.3) if line.startswith(b"USBL")]
    assert ca.ask(b"AT@ZU1") == b"OK" and cc.ask(b"AT@ZU1") == b"OK"
    d = math.sqrt(30 ** 2 + 40 ** 2 + 10 ** 2)
    ranges = []
    for _ in range(4):
        cb.send(b"AT*SENDIM,2,255,noack,hi")  # heard by both USBLs
        assert cb.expect(b"OK")[0] == b"OK"
        ca.expect(b"RECVIM")
        long = usbl_fields(ca.expect(b"USBLLONG")[0])
        assert long[2] == 2  # the remote's address
        # mounted with yaw 90°: the transceiver's x is east, its y south; E/N/U is the world's
        assert long[3:6] == pytest.approx([40, -30, 10], abs=5e-5)
        assert long[6:9] == pytest.approx([40, 30, -10], abs=5e-5)
        assert long[9:12] == pytest.approx([0, 0, math.pi / 2], abs=5e-5)
        assert long[12] == round(d / 1500 * 1e6) and long[15] == 0.0  # ptime µs; accuracy
        angles = ca.expect(b"USBLANGLES")[0].split(b",")
        assert len(angles) == 14
        assert float(angles[6]) == pytest.approx(math.atan2(40, 30), abs=5e-5)  # world bearing
        noisy = usbl_fields(cc.expect(b"USBLLONG")[0])
        ranges.append(math.dist((0, 0, 0), noisy[3:6]))
        # the configured σ, z-bounded.  c's id, so its USBL stream (seed/id/usbl), is new each run: each
        # bound must hold for any stream.  Range within 5.5 σ_r: P(|z| > 5.5) = 3.8e-8 per fix, 1.5e-7 for
        # the four (5 σ_r was 5.7e-7 per fix, 2.3e-6 per run).  Position within 5 times the reported
        # accuracy, whose square is the sum of the three components' variances (0.5 m, ~1.8 m, ~1.8 m): at
        # most P(χ²₃ > 25·6.6/3.17 = 52) = 3e-11 per fix
        assert abs(ranges[-1] - d) < 5.5 * sigma_r
        assert math.dist(noisy[6:9], (40, 30, -10)) < 5 * noisy[15]
        assert noisy[15] == pytest.approx(math.sqrt(sigma_r ** 2 + 2 * (ranges[-1] * math.radians(sigma_b)) ** 2),
                                          abs=2e-4)
    assert len(set(ranges)) == 4  # drawn anew for each fix
    # after an exchange the USBL started (an ack IM), the fix comes with DELIVEREDIM
    ca.send(b"AT*SENDIM,1,2,ack,x")
    assert ca.expect(b"OK")[0] == b"OK"
    assert ca.expect(b"DELIVEREDIM")[0] == b"DELIVEREDIM,2"
    assert usbl_fields(ca.expect(b"USBLLONG")[0])[3:6] == pytest.approx([40, -30, 10], abs=5e-5)
    for client in (ca, cb, cc):
        client.close()


def test_an_ack_im_dropped_before_the_air_is_failed_at_once_and_the_modem_is_free_again(tmp_path):
    daemon, a, b, ca, cb = two_modems(tmp_path, 100, a_extra=", fifo_bytes: 8")
    try:
        ca.send(b"AT*SENDIM,20,2,ack,01234567890123456789")  # more than the FIFO holds
        assert ca.expect(b"OK")[0] == b"OK"
        assert ca.expect(b"FAILEDIM")[0] == b"FAILEDIM,2"
        assert ca.ask(b"AT?DI") == b"EMPTY"
        ca.send(b"AT*SENDIM,4,2,ack,abcd")
        assert ca.expect(b"OK")[0] == b"OK"
        assert ca.expect(b"DELIVEREDIM")[0] == b"DELIVEREDIM,2"
        assert cb.expect(b"RECVIM")[1] == b"abcd"
        ca.close(), cb.close()
        daemon.stop()
        assert [e["cause"] for e in daemon.trace_events() if e.get("link") == a and e["ev"] == "drop"] == ["fifo"]
    finally:
        daemon.close()


def test_a_burst_is_acknowledged_on_the_channel_too(tmp_path):
    d = 300.0
    daemon, a, b, ca, cb = two_modems(tmp_path, d)
    try:
        ca.send(b"AT*SEND,5,2,burst")
        assert ca.expect(b"OK")[0] == b"OK"
        text, body = cb.expect(b"RECV,")
        assert body == b"burst" and text.split(b",")[7] == str(round(d / 1500 * 1e6)).encode()  # ptime µs
        ca.settle(1.0)
        ca.close(), cb.close()
        daemon.stop()
        events = daemon.trace_events()
        [data_tx] = events_of(events, a, "tx")
        [ack_tx] = events_of(events, b, "tx")
        assert ack_tx["kind"] == "modem_ack"
        assert ack_tx["t"] == pytest.approx(data_tx["t"] + 5 * 8 / BITRATE + d / 1500 + TURN, **EXACT)
        assert [e.get("kind") for e in events_of(events, a, "rx")] == ["modem_ack"]
    finally:
        daemon.close()
