"""DESIGN.md's timing and loss model, stated as exact arithmetic on tiny networks."""

import math

import pytest

from hilgate.models.errormodel import ErrorModel
from hilgate.models.medium import Channel
from hilgate.models.trajectories import Piecewise, path_segments
from netkit import Net

EXACT = dict(abs=1e-12)


def test_design_example_delivers_at_exactly_1_95_s():
    # 1500 m on a 1500 m/s channel, 1000 bit/s, 100 bytes, tx delay 0.1 s, rx delay 0.05 s:
    # t_s = 0.1, T = 0.8, tau = 1.0 -> arrival ends 1.9, delivered 1.95.
    net = Net(Channel("ac", 1500.0))
    params = dict(bitrate_bps=1000, tx_delay_s=0.1, rx_delay_s=0.05)
    net.modem("a", (0, 0, 0), **params)
    net.modem("b", (1500, 0, 0), **params)
    net.send("a", "b", 100)
    net.run()
    [(t_tx, *_)] = net.of("tx", "a")
    [(t_rx, *_)] = net.of("rx", "b")
    assert t_tx == pytest.approx(0.1, **EXACT)
    assert t_rx == pytest.approx(1.95, **EXACT)
    assert net.delivered["b"][0][0] == pytest.approx(1.95, **EXACT)


def test_min_delay_of_the_channel_adds_to_propagation():
    net = Net(Channel("ac", 1500.0, min_delay_s=0.25))
    net.modem("a", (0, 0, 0), bitrate_bps=800)
    net.modem("b", (0, 300, 400), bitrate_bps=800)  # 500 m
    net.send("a", "b", 10)  # T = 0.1
    net.run()
    [(t_rx, *_)] = net.of("rx", "b")
    assert t_rx == pytest.approx(0.1 + 0.25 + 500 / 1500, **EXACT)


def test_fifo_wait_then_intrinsic_delay_before_each_frame():
    # Three frames at t=0: each starts tx_delay after the previous one ends.
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (0, 0, 0), bitrate_bps=1000, tx_delay_s=0.01)
    net.modem("b", (150, 0, 0), bitrate_bps=1000)
    for _ in range(3):
        net.send("a", "b", 50)  # T = 0.4
    net.run()
    starts = [t for t, *_ in net.of("tx", "a")]
    assert starts == pytest.approx([0.01, 0.42, 0.83], **EXACT)
    delays = [t - f.t0 for t, f in net.delivered["b"]]
    # end-to-end = wait-in-FIFO + tx_delay + T + tau + rx_delay
    assert delays == pytest.approx([0.01 + 0.4 + 0.1, 0.42 + 0.4 + 0.1, 0.83 + 0.4 + 0.1], **EXACT)


def test_fifo_overflow_drops_and_counts_in_bytes():
    net = Net()
    a = net.modem("a", (0, 0, 0), bitrate_bps=1000, fifo_bytes=250)
    net.modem("b", (10, 0, 0))
    for _ in range(10):
        net.send("a", "b", 100)
    # The first frame went straight to the PHY, two wait in the FIFO (200 <= 250), seven are dropped.
    assert a.queued_bytes == 200
    drops = net.of("drop", "a")
    assert len(drops) == 7 and all(cause == "fifo" for *_, cause in drops)
    assert a.stats.fifo_drops == 7
    assert a.stats.fifo_peak_bytes == 200
    net.run()
    assert len(net.of("rx", "b")) == 3


def test_frame_larger_than_the_fifo_is_dropped_even_when_idle():
    net = Net()
    net.modem("a", fifo_bytes=50)
    net.modem("b", (1, 0, 0))
    net.send("a", "b", 51)
    assert [e[4] for e in net.of("drop")] == ["fifo"]


def test_overlapping_arrivals_collide_at_the_receiver():
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (-300, 0, 0), bitrate_bps=1000)
    net.modem("c", (300, 0, 0), bitrate_bps=1000)
    net.modem("b", (0, 0, 0), bitrate_bps=1000)
    net.send("a", "b", 100)                # arrives [0.2, 1.0]
    net.send("c", "b", 100, at=0.79)       # arrives [0.99, 1.79]: overlaps by 10 ms
    net.run()
    assert net.of("rx") == []
    assert [(link, cause) for _, _, link, _, cause in net.of("err")] == [("b", "col"), ("b", "col")]


def test_arrivals_that_only_touch_do_not_collide():
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (-300, 0, 0), bitrate_bps=1000)
    net.modem("c", (300, 0, 0), bitrate_bps=1000)
    net.modem("b", (0, 0, 0), bitrate_bps=1000)
    net.send("a", "b", 100)            # [0.2, 1.0]
    net.send("c", "b", 100, at=0.8)    # [1.0, 1.8]: strictly no overlap
    net.run()
    assert len(net.of("rx", "b")) == 2 and net.of("err") == []


def test_collision_only_where_the_arrivals_overlap():
    # a and c broadcast 10 B (T = 80 ms) at once. At b, midway, both arrive over [0.2, 0.28]: collision.
    # At d, 1500 m beyond a, they arrive over [1.0, 1.08] and [1.4, 1.48]: both good.
    # a and c hear each other 600 m apart over [0.4, 0.48], after their own transmissions: both good.
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (-300, 0, 0), bitrate_bps=1000)
    net.modem("c", (300, 0, 0), bitrate_bps=1000)
    net.modem("b", (0, 0, 0), bitrate_bps=1000)
    net.modem("d", (-1800, 0, 0), bitrate_bps=1000)
    net.send("a", None, 10)
    net.send("c", None, 10)
    net.run()
    assert [(link, cause) for _, _, link, _, cause in net.of("err")] == [("b", "col"), ("b", "col")]
    received = sorted((round(t, 9), link) for t, _, link, *_ in net.of("rx"))
    assert received == [(0.48, "a"), (0.48, "c"), (1.08, "d"), (1.48, "d")]


def test_half_duplex_receiver_transmitting_loses_the_arrival():
    # a sends 100 B: on air [0, 0.8], at b (150 m) over [0.1, 0.9].
    # b sends 10 B at 0.5: on air [0.5, 0.58] inside that arrival, so b loses a's frame;
    # b's frame reaches a over [0.6, 0.68] while a is still transmitting, so a loses it too.
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (0, 0, 0), bitrate_bps=1000)
    net.modem("b", (150, 0, 0), bitrate_bps=1000)
    net.send("a", "b", 100)
    net.send("b", "a", 10, at=0.5)
    net.run()
    assert [(round(t, 9), link, cause) for t, _, link, _, cause in net.of("err")] == [
        (0.68, "a", "col"), (0.9, "b", "col")]
    assert net.of("rx") == []


def test_full_duplex_receiver_keeps_the_arrival():
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (0, 0, 0), bitrate_bps=1000, duplex="full")
    net.modem("b", (150, 0, 0), bitrate_bps=1000, duplex="full")
    net.send("a", "b", 100)
    net.send("b", "a", 10, at=0.5)
    net.run()
    assert net.of("err") == []
    assert len(net.of("rx")) == 2


def test_arrival_already_under_way_when_the_receiver_starts_transmitting_collides():
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (0, 0, 0), bitrate_bps=1000)
    net.modem("b", (1500, 0, 0), bitrate_bps=1000)
    net.send("a", "b", 100)            # arrives at b over [1.0, 1.8]
    net.send("b", "a", 10, at=1.7)     # b starts transmitting inside the arrival
    net.run()
    assert ("b", "col") in [(link, cause) for _, _, link, _, cause in net.of("err")]


def test_error_and_collision_together_are_mult():
    net = Net(Channel("ac", 1500.0))
    lossy = ErrorModel("packet", "1")
    net.modem("a", (-300, 0, 0), bitrate_bps=1000)
    net.modem("c", (300, 0, 0), bitrate_bps=1000)
    net.modem("b", (0, 0, 0), bitrate_bps=1000, error=lossy)
    net.send("a", "b", 100)
    net.send("c", "b", 100)
    net.send("a", "b", 100, at=5.0)  # alone: error only
    net.run()
    causes = [cause for *_, cause in net.of("err", "b")]
    assert causes == ["mult", "mult", "prop"]


def test_out_of_range_means_no_arrival_at_all():
    net = Net(Channel("rf", 2.25e7))
    net.modem("a", (0, 0, 0), range_m=(0.5, 6.0), channel="rf")
    net.modem("b", (6.5, 0, 0), channel="rf")
    net.modem("c", (0.3, 0, 0), channel="rf")
    net.modem("d", (5.0, 0, 0), channel="rf")
    net.send("a", "b", 20)
    net.send("a", "c", 20, at=1.0)
    net.send("a", None, 20, at=2.0)
    net.run()
    assert [(link, cause) for _, _, link, _, cause in net.of("err")] == [("b", "range"), ("c", "range")]
    # the broadcast is heard by d only; d is the only receiver the medium created arrivals for
    assert [link for _, _, link, *_ in net.of("rx")] == ["d"]
    assert net.medium.arrivals == 3


def test_a_frame_that_cannot_be_judged_for_want_of_a_pose_is_traced_at_each_radio_that_would_judge_it():
    # issue 24 item 7: before a live vehicle's first pose its frames are heard by nobody and frames to it
    # reach it nowhere; each is an err with cause no_pose, broadcast or not, never silence
    from hilgate.sim.live_vehicle import LiveVehicle

    rov = LiveVehicle("rov")  # no pose yet
    net = Net(Channel("ac", 1500.0))
    net.modem("top", (0, 0, 0), bitrate_bps=1000)
    net.modem("rov", rov, bitrate_bps=1000)
    net.modem("buoy", (100, 0, 0), bitrate_bps=1000)
    net.send("top", "rov", 10)          # unicast to the vehicle without a pose
    net.send("top", None, 10, at=1.0)   # broadcast: buoy hears it, rov cannot be judged
    net.send("rov", None, 10, at=2.0)   # from the vehicle without a pose: neither top nor buoy can judge it
    net.send("rov", "buoy", 10, at=3.0)
    net.clock.at(4.0, lambda: rov.update("mavlink", 4.0, {"x": 150.0, "y": 0.0, "z": 0.0}))
    net.send("top", "rov", 10, at=5.0)  # its pose came: heard
    net.run()
    errors = [(round(t), link, cause) for t, _, link, _, cause in net.of("err")]
    assert errors == [(0, "rov", "no_pose"), (1, "rov", "no_pose"), (2, "top", "no_pose"), (2, "buoy", "no_pose"),
                      (3, "buoy", "no_pose")]
    assert [(round(t), link) for t, _, link, *_ in net.of("rx")] == [(1, "buoy"), (5, "rov")]
    # and counted, per link and cause
    assert {name: modem.stats.lost for name, modem in net.modems.items()} == \
        {"top": {"no_pose": 1}, "rov": {"no_pose": 2}, "buoy": {"no_pose": 2}}


def test_range_is_the_senders():
    net = Net(Channel("rf", 2.25e7))
    net.modem("far_reaching", (0, 0, 0), range_m=(0.0, 100.0), channel="rf")
    net.modem("short", (50, 0, 0), range_m=(0.0, 10.0), channel="rf")
    net.send("far_reaching", "short", 10)
    net.send("short", "far_reaching", 10, at=1.0)
    net.run()
    assert [link for _, _, link, *_ in net.of("rx")] == ["short"]
    assert [(link, cause) for _, _, link, _, cause in net.of("err")] == [("far_reaching", "range")]


def test_separate_tx_and_rx_channels():
    net = Net(Channel("up", 1500.0), Channel("down", 1500.0))
    net.modem("buoy", (0, 0, 0), tx_channel="down", rx_channel="up")
    net.modem("auv", (150, 0, 0), tx_channel="up", rx_channel="down")
    net.modem("eavesdropper", (150, 0, 0), tx_channel="up", rx_channel="up", address=9)
    net.send("buoy", None, 10)
    net.run()
    assert [link for _, _, link, *_ in net.of("rx")] == ["auv"]


def test_unicast_is_delivered_only_to_the_addressed_receiver_unless_promiscuous():
    net = Net()
    net.modem("a", (0, 0, 0))
    net.modem("b", (100, 0, 0))
    net.modem("c", (200, 0, 0))
    net.modem("spy", (300, 0, 0), promiscuous=True)
    net.send("a", "b", 10)
    net.run()
    assert sorted(link for _, _, link, *_ in net.of("rx")) == ["b", "spy"]


def test_moving_vehicle_changes_the_delay_as_its_path_says():
    # b starts 150 m away and moves away at 15 m/s along x; t_s = 0, 10, 20 s.
    path = Piecewise(path_segments((150, 0, 0), [{"to": (1650, 0, 0), "speed_mps": 15.0}]))
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (0, 0, 0), bitrate_bps=1000)
    net.modem("b", path, bitrate_bps=1000)
    for t in (0.0, 10.0, 20.0):
        net.send("a", "b", 10, at=t)  # T = 0.08
    net.run()
    delays = [t - f.t0 for t, f in net.delivered["b"]]
    # distance at t_s: 150, 300, 450 m -> tau 0.1, 0.2, 0.3 s
    assert delays == pytest.approx([0.18, 0.28, 0.38], **EXACT)


def test_tx_jitter_never_makes_the_extra_delay_negative():
    net = Net()
    net.modem("a", (0, 0, 0), tx_delay_s=0.0, tx_jitter_s=1.0, bitrate_bps=1e6)
    net.modem("b", (1, 0, 0), rx_jitter_s=1.0)
    for i in range(200):
        net.send("a", "b", 10, at=i * 10.0)
    net.run()
    starts = [t for t, *_ in net.of("tx", "a")]
    assert all(t >= i * 10.0 for i, t in enumerate(starts))
    # about half of the Gaussian draws are negative and clamp to zero delay
    on_time = sum(1 for i, t in enumerate(starts) if t == i * 10.0)
    assert 60 <= on_time <= 140
    assert all(t >= f.t0 for t, f in net.delivered["b"])


def test_frames_queued_at_the_receiver_do_not_block_reception_until_it_transmits():
    # b has a frame for later; until it goes on air b hears a normally.
    net = Net(Channel("ac", 1500.0))
    net.modem("a", (0, 0, 0), bitrate_bps=1000)
    net.modem("b", (1500, 0, 0), bitrate_bps=1000)
    net.send("a", "b", 10)
    net.send("b", "a", 10, at=1.08)  # exactly when the arrival ends: touching, not overlapping
    net.run()
    assert math.isclose(net.delivered["b"][0][0], 1.08)
    assert math.isclose(net.delivered["a"][0][0], 1.08 + 1.08)


def test_the_phy_report_for_an_emulated_modem_gives_the_models_times():
    """What an emulated modem's SENDSTART/SENDEND/RECVSTART/RECVEND/RECVFAILED are made of: the
    transmission [t_s, t_s + T] and the arrival [t_s + τ, t_s + τ + T], exactly; nothing is scheduled
    for a modem nobody watches."""
    net = Net(Channel("ac", 1500.0))
    a = net.modem("a", (0, 0, 0), bitrate_bps=1000, tx_delay_s=0.01)
    b = net.modem("b", (150, 0, 0), bitrate_bps=1000)
    c = net.modem("c", (0, 150, 0), bitrate_bps=1000, error=ErrorModel("packet", "1"))
    seen = []
    for modem in (a, b, c):
        modem.on_phy = lambda kind, frame, start, end, cause, name=modem.id: seen.append(
            (name, kind, frame.id, start, end, cause))
    first = net.send("a", "b", 50)   # T = 0.4, τ = 0.1
    net.run()
    lost = net.send("a", "c", 50)
    net.run()
    assert seen[:3] == [("a", "tx", first.id, 0.01, pytest.approx(0.41, **EXACT), None),
                        ("b", "rx_start", first.id, pytest.approx(0.11, **EXACT), pytest.approx(0.51, **EXACT), None),
                        ("b", "rx_end", first.id, None, pytest.approx(0.51, **EXACT), None)]
    assert [(name, kind, cause) for name, kind, _, _, _, cause in seen[3:]] == [
        ("a", "tx", None), ("c", "rx_start", None), ("c", "rx_end", "prop")]
    assert all(frame_id == lost.id for _, _, frame_id, *_ in seen[3:])
    events = net.clock.events
    b.on_phy = c.on_phy = a.on_phy = None
    net.send("a", "b", 50)
    net.run()
    assert net.clock.events - events == 3  # intrinsic delay, end of transmission, end of arrival


def test_a_modem_readdressed_and_frames_withdrawn_from_its_fifo():
    """AT!AL and ATZ as the models see them: the new address is what frames carry and what receivers
    match; frames taken back from the FIFO are traced as drops and never go on air."""
    net = Net(Channel("ac", 1500.0))
    a = net.modem("a", (0, 0, 0), bitrate_bps=1000)
    b = net.modem("b", (150, 0, 0), bitrate_bps=1000)
    b.set_address(9)
    frames = [net.send("a", "b", 50) for _ in range(3)]   # to 9 now; the first goes on air at once
    assert frames[0].dst_addr == 9
    assert a.withdraw(lambda frame: frame is frames[2], "cleared") == 1
    assert a.queued_bytes == 50
    net.run()
    assert [f.id for _, f in net.delivered["b"]] == [frames[0].id, frames[1].id]
    assert [(e[3], e[4]) for e in net.of("drop", "a")] == [(frames[2].id, "cleared")]
    assert len(net.of("tx", "a")) == 2
