"""One propagation model per channel gives every path its delay and loss: static and moving pairs, an
emulated modem's delay and a MAC's timing all ask it, so a channel that changes it changes them all."""

from dataclasses import dataclass

import pytest

from hilgate.models.medium import Channel
from hilgate.models.path import bind_path
from hilgate.models.propagation import StraightLine
from hilgate.models.trajectories import Piecewise, Segment
from netkit import Net

SPEED = 2.25e7  # a radio channel: 1.8 m take 80 ns
HERE, THERE, ELSEWHERE = (0.0, 0.0, 0.0), (1.8, 0.0, 0.0), (0.0, 1.8, 0.0)


@dataclass(frozen=True)
class OneSecondMore:
    """A channel whose paths all take one second more (what a ray-traced model might add)."""

    line: StraightLine
    positional = False
    distance_only = False  # (listed pair by pair, as any model that does not say otherwise)

    def delay(self, d, a=None, b=None):
        return 1.0 + self.line.delay(d, a, b)

    def bind(self, sender, receiver):
        return bind_path(sender, receiver)


def parked_until(t, position, then):
    """A vehicle at ``position`` that leaves it at ``t``: a moving pair for the medium from the start."""
    return Piecewise([Segment(0.0, t, position, position), Segment(t, t + 10.0, position, then)])


def heard_at(channel):
    net = Net(channel)
    net.modem("a", HERE)
    static = net.modem("static", THERE)
    moving = net.modem("moving", parked_until(100.0, ELSEWHERE, (0.0, 50.0, 0.0)))
    assert static.radio.pose.static and not moving.radio.pose.static
    net.send("a", None, 10, at=1.0)
    net.run()
    airtime = net.modems["a"].airtime(10)
    return net.delivered["static"][0][0] - airtime, net.delivered["moving"][0][0] - airtime


def test_a_static_and_a_moving_receiver_hear_a_frame_after_the_same_delay():
    """The issue's example: with one second more on every path, both arrive at t = 2.00000008 (the
    moving pair used to get 1.00000008 from a copy of the formula)."""
    static, moving = heard_at(Channel("rf", SPEED, propagation=OneSecondMore(StraightLine(SPEED))))
    assert static == moving == pytest.approx(2.00000008, abs=1e-12)


def test_the_straight_line_is_every_scene_channel():
    channel = Channel("ac", 1500.0, 0.01)
    assert channel.propagation == StraightLine(1500.0, 0.01)
    assert channel.propagation.delay(1500.0) == 0.01 + 1.0
    static, moving = heard_at(Channel("rf", SPEED))
    assert static == moving == pytest.approx(1.00000008, abs=1e-12)


def test_an_emulated_modems_delay_and_a_macs_timing_ask_the_same_model():
    net = Net(Channel("rf", SPEED, propagation=OneSecondMore(StraightLine(SPEED))))
    a = net.modem("a", HERE)
    b = net.modem("b", THERE, range_m=(0.0, 100.0))
    assert net.medium.propagation_delay(a.radio, b.radio, 0.0) == pytest.approx(1.0 + 1.8 / SPEED, abs=1e-15)
    assert b.tau_at(100.0) == pytest.approx(1.0 + 100.0 / SPEED, abs=1e-15)


class DepthDelay:
    """One arrival of a positional channel: its delay grows with the receiver's depth (as BELLHOP's
    eigenrays do), no loss."""

    def __init__(self, delay):
        self.delay = delay

    def per(self, d, size):
        return 0.0


class ByDepth:
    """A pair's loss model on a positional channel, looked up at both ends' positions."""

    def __init__(self, bound):
        self.bound = bound

    def at(self, a, b):
        return DepthDelay(0.25 + abs(b[2]) * 0.125)


@dataclass(frozen=True)
class WaterLike:
    """A positional propagation (the BELLHOP channel's kind): a pair's delay comes from its bound model
    at both ends' positions, and its pair-less answer (a MAC's timing at a range) differs from it."""

    line: StraightLine
    positional = True
    distance_only = False

    def delay(self, d, a=None, b=None):
        return self.line.delay(d)

    def bind(self, sender, receiver):
        bound = bind_path(sender, receiver)
        return bound._replace(model=ByDepth(bound.model))


def test_on_a_positional_channel_an_emulated_modem_is_told_the_delay_its_arrivals_take():
    """BELLHOP in the seam: the delay an emulated modem reports (AT?T) and an acknowledgement's timing
    are the arrival's own (the pair's lookup at both ends' positions plus the channel's min_delay_s),
    for a static and a moving receiver, not the channel's pair-less answer at the mean sound speed."""
    channel = Channel("ac", 1500.0, 0.01, propagation=WaterLike(StraightLine(1500.0, 0.01)))
    net = Net(channel)
    a = net.modem("a", (0.0, 0.0, 0.0))
    static = net.modem("static", (30.0, 0.0, 4.0))
    moving = net.modem("moving", parked_until(100.0, (0.0, 30.0, 8.0), (0.0, 60.0, 8.0)))
    net.send("a", None, 10, at=1.0)
    net.run()
    airtime = a.airtime(10)
    heard = {name: net.delivered[name][0][0] - airtime - 1.0 for name in ("static", "moving")}
    assert heard == pytest.approx({"static": 0.01 + 0.25 + 0.5, "moving": 0.01 + 0.25 + 1.0}, abs=1e-12)
    assert net.medium.propagation_delay(a.radio, static.radio, 1.0) == pytest.approx(heard["static"], abs=1e-12)
    assert net.medium.propagation_delay(a.radio, moving.radio, 1.0) == pytest.approx(heard["moving"], abs=1e-12)
    assert a.tau_at(1500.0) == pytest.approx(0.01 + 1.0, abs=1e-12)  # no positions: the distance alone
