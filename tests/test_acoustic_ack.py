"""The modem's own acknowledgements (models/acoustic_ack.py), as exact arithmetic on two modems in
virtual time: the ACK is a frame on the channel, retries follow its loss, the reports come when the
model says."""

import math

import pytest

from hilgate.models.acoustic_ack import GUARD_S, MODEM_ACK
from hilgate.models.errormodel import ErrorModel
from hilgate.models.medium import Channel
from hilgate.models.trajectories import Piecewise, path_segments
from netkit import Net

EXACT = dict(abs=1e-9)
BITRATE = 1900.0
TX_DELAY = 0.001
TURN = 0.27
ACK_BYTES = 6
MAX_RANGE = 8000.0


def evologics(**extra):
    params = dict(bitrate_bps=BITRATE, tx_delay_s=TX_DELAY, ack_bytes=ACK_BYTES, ack_turnaround_s=TURN,
                  range_m=(0.0, MAX_RANGE))
    params.update(extra)
    return params


def acked_net(distance, a_extra=None, b_extra=None, seed=1):
    net = Net(Channel("ac", 1500.0), seed=seed)
    a = net.modem("a", (0, 0, 0), **evologics(**(a_extra or {})))
    b = net.modem("b", (distance, 0, 0), **evologics(**(b_extra or {})))
    outcomes = []
    a.acks.on_outcome = lambda frame, ok, tau: outcomes.append((net.clock.now(), frame.id, ok, tau))
    return net, a, b, outcomes


def send_acked(net, size, retries, at=None, app=True):
    frame = net.send("a", "b", size, at=at)
    frame.ack = retries
    if app:
        frame.app_frame = "an application's frame"  # delivered again when retransmitted (flows' are not)
    return frame


def test_an_acked_frame_is_reported_delivered_when_its_ack_ends_at_the_sender():
    d, size = 1000.0, 20
    net, a, b, outcomes = acked_net(d)
    frame = send_acked(net, size, 3)
    net.run()
    tau, t_im, t_ack = d / 1500, size * 8 / BITRATE, ACK_BYTES * 8 / BITRATE
    expected = TX_DELAY + t_im + tau + TURN + t_ack + tau  # t_send = 0
    assert outcomes == [(pytest.approx(expected, **EXACT), frame.id, True, pytest.approx(tau, **EXACT))]
    # the ACK is a frame on air: sent by b after its turnaround, heard by a
    [(t_ack_tx, _, _, ack_id, _)] = net.of("tx", "b")
    assert net.events.kinds[ack_id] == MODEM_ACK
    assert t_ack_tx == pytest.approx(TX_DELAY + t_im + tau + TURN, **EXACT)
    assert [e[0] for e in net.of("rx", "a")] == [pytest.approx(expected, **EXACT)]
    assert a.idle and b.idle
    assert len(net.delivered["b"]) == 1 and not net.of("retx")


def test_the_sender_is_not_idle_while_it_awaits_the_ack():
    net, a, b, outcomes = acked_net(1500.0)
    send_acked(net, 10, 0)
    net.run(until=1.0)  # data on air 0.001..0.043, ACK back at ~2.3 s
    assert not a.idle and not outcomes
    net.run()
    assert a.idle and outcomes[0][2] is True


def test_an_ack_lost_to_the_error_model_brings_retries_then_a_failure_at_the_model_times():
    d, size, retries = 1200.0, 32, 3
    # every arrival at a (the ACKs) is lost; b hears the data well
    net, a, b, outcomes = acked_net(d, a_extra=dict(error=ErrorModel("packet", "1")))
    frame = send_acked(net, size, retries)
    net.run()
    tau_max = MAX_RANGE / 1500
    t_im, t_ack = size * 8 / BITRATE, ACK_BYTES * 8 / BITRATE
    wait = 2 * tau_max + TURN + t_ack + GUARD_S
    attempt = TX_DELAY + t_im + wait
    assert outcomes == [(pytest.approx((retries + 1) * attempt, **EXACT), frame.id, False, None)]
    assert [e[0] for e in net.of("tx", "a")] == pytest.approx(
        [k * attempt + TX_DELAY for k in range(retries + 1)], **EXACT)
    assert [e[0] for e in net.of("retx", "a")] == pytest.approx([k * attempt for k in range(1, retries + 1)], **EXACT)
    assert [e[0] for e in net.of("giveup", "a")] == pytest.approx([(retries + 1) * attempt], **EXACT)
    # every transmission reached b and was answered; each ACK was lost at a, traced with its cause
    assert len(net.delivered["b"]) == retries + 1  # duplicates, as real receivers see them
    assert len(net.of("dup", "b")) == retries
    assert len(net.of("tx", "b")) == retries + 1
    assert [e[4] for e in net.of("err", "a")] == ["prop"] * (retries + 1)
    assert a.idle


def test_a_lost_ack_is_recovered_by_a_retry():
    # the ACK error rate at a is 0.5; the seed gives a first ACK lost and a later one through
    for seed in range(1, 50):
        net, a, b, outcomes = acked_net(500.0, a_extra=dict(error=ErrorModel("packet", "0.5")), seed=seed)
        send_acked(net, 16, 3)
        net.run()
        if net.of("retx") and outcomes[0][2]:
            break
    else:
        pytest.fail("no seed gave a retry that succeeded")
    retx = len(net.of("retx", "a"))
    assert len(net.delivered["b"]) == retx + 1
    assert outcomes[0][2] is True


def test_the_ack_collides_like_any_frame():
    d = 1500.0
    net, a, b, outcomes = acked_net(d)
    c = net.modem("c", (0, 10, 0), **evologics())
    send_acked(net, 10, 0)
    t_im, t_ack = 10 * 8 / BITRATE, ACK_BYTES * 8 / BITRATE
    ack_at_a = TX_DELAY + t_im + 1.0 + TURN + 1.0  # start of the ACK's arrival at a
    # c, 10 m from a, sends a long broadcast that covers the ACK's arrival at a
    c_frame = net.send("c", None, 40, at=ack_at_a - 0.1 - TX_DELAY)
    net.run()
    assert outcomes[0][2] is False
    errors = {e[3]: e[4] for e in net.of("err", "a")}
    ack_id = next(e[3] for e in net.of("tx", "b"))
    assert errors == {ack_id: "col", c_frame.id: "col"}
    assert net.of("giveup", "a")


def test_an_ack_beyond_the_range_of_the_receiver_never_comes_back():
    # b hears a (a's range is 8 km) but b's range is 500 m: its ACK never reaches a
    net, a, b, outcomes = acked_net(1000.0, b_extra=dict(range_m=(0.0, 500.0)))
    send_acked(net, 10, 1)
    net.run()
    assert [o[2] for o in outcomes] == [False]
    assert len(net.delivered["b"]) == 2
    assert [e[4] for e in net.of("err", "a")] == ["range", "range"]


@pytest.mark.parametrize("d", [4700.0, 7000.0, 7999.0])
def test_delivery_far_away_is_never_reported_failed_first(d):
    # issue 13 item 2: a fixed 2·airtime + 3 s lost deliveries beyond ~4.6 km
    net, a, b, outcomes = acked_net(d)
    send_acked(net, 64, 3)
    net.run()
    tau = d / 1500
    expected = TX_DELAY + 64 * 8 / BITRATE + tau + TURN + ACK_BYTES * 8 / BITRATE + tau
    assert [(o[0], o[2]) for o in outcomes] == [(pytest.approx(expected, **EXACT), True)]
    assert not net.of("retx")


def test_the_wait_is_never_shorter_than_a_round_trip_at_maximum_range():
    net, a, b, outcomes = acked_net(10.0)
    assert a.acks.wait_s() >= 2 * MAX_RANGE / 1500 + TURN + ACK_BYTES * 8 / BITRATE


def test_an_ack_due_while_the_receiver_transmits_waits_for_its_phy():
    d = 150.0
    net, a, b, outcomes = acked_net(d)
    frame = send_acked(net, 10, 0)
    t_im = 10 * 8 / BITRATE
    t_e = TX_DELAY + t_im + d / 1500
    # b starts a long broadcast just before its ACK is due: the ACK goes right after it
    other = net.send("b", None, 100, at=t_e + TURN - 0.01 - TX_DELAY)
    net.run()
    tx_b = net.of("tx", "b")
    assert [e[3] for e in tx_b][0] == other.id
    assert tx_b[1][0] == pytest.approx(t_e + TURN - 0.01 + 100 * 8 / BITRATE, **EXACT)
    assert outcomes[0][1] == frame.id


def test_a_moving_receiver_gives_the_round_trip_it_had():
    # b moves away at 1 m/s: the measured one-way time is half the round trip (out at t_s, back later)
    source = Piecewise(path_segments([1000, 0, 0], [{"to": [2000, 0, 0], "speed_mps": 1.0}]))
    net = Net(Channel("ac", 1500.0))
    a = net.modem("a", (0, 0, 0), **evologics())
    net.modem("b", source, **evologics())
    outcomes = []
    a.acks.on_outcome = lambda frame, ok, tau: outcomes.append((net.clock.now(), ok, tau))
    send_acked(net, 10, 0)
    net.run()
    [(t, ok, tau)] = outcomes
    assert ok and 1000 / 1500 < tau < 1003 / 1500
    assert math.isfinite(t)


def test_broadcasts_and_frames_without_the_request_are_not_acknowledged():
    net, a, b, outcomes = acked_net(100.0)
    frame = net.send("a", None, 10)
    frame.ack = 3
    net.send("a", "b", 10)
    net.run()
    assert not outcomes and not net.of("tx", "b") and a.idle


def test_a_flows_duplicates_are_traced_and_not_delivered_again():
    net, a, b, outcomes = acked_net(800.0, a_extra=dict(error=ErrorModel("packet", "1")))
    send_acked(net, 10, 2, app=False)
    net.run()
    assert len(net.delivered["b"]) == 1 and len(net.of("dup", "b")) == 2 and len(net.of("tx", "b")) == 3


ACKED_FLOW = """\
name: acked
seed: 4
duration_s: 100
channels: {ac: {speed_mps: 1500}}
vehicles:
  a: {pose: {static: [0, 0, 0]}}
  b: {pose: {static: [750, 0, 0]}}
links:
  la: {vehicle: a, model: evologics-s2cr-7-17, range_m: [0, 1500], error: {expr: "0.5"}}
  lb: {vehicle: b, model: evologics-s2cr-7-17, range_m: [0, 1500]}
flows:
  - {from: la, to: lb, size_bytes: 20, interval_s: 10, stop_s: 95, ack_retries: 2}
"""


def test_hilgate_sim_runs_acknowledged_flows_with_acks_on_the_channel():
    import io
    import json

    from hilgate.scene import load_scene_text
    from hilgate.sim.simulate import simulate

    trace = io.StringIO()
    summary = simulate(load_scene_text(ACKED_FLOW, "acked.yaml"), trace=trace)
    events = [json.loads(line) for line in trace.getvalue().splitlines()]

    def of(ev, link, kind=None):
        return [e for e in events if e["ev"] == ev and e["link"] == link and e.get("kind") == kind]

    data_tx, acks_tx = of("tx", "la"), of("tx", "lb", MODEM_ACK)
    retx, giveups, dups = of("retx", "la"), of("giveup", "la"), of("dup", "lb")
    [flow] = summary["flows"]
    assert flow["offered"] == 10 and len(data_tx) == 10 + len(retx)
    assert retx and len(retx) < 20  # some ACKs lost (PER 0.5 at la), some frames recovered by a retry
    assert len(acks_tx) == len(data_tx)  # b answered every transmission it heard
    assert len(dups) == len(retx) and flow["rx_packets"] == 10  # duplicates are traced, not counted twice
    assert len(giveups) == 10 - len(of("rx", "la", MODEM_ACK))
    t_im, tau = 20 * 8 / BITRATE, 750 / 1500
    for ack in acks_tx:  # each ACK leaves b a turnaround after the data frame it answers has arrived
        sent = max(e["t"] for e in data_tx if e["t"] < ack["t"])
        assert ack["t"] == pytest.approx(sent + t_im + tau + TURN, **EXACT)
