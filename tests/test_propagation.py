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
    assert net.medium.propagation_delay(a, b, 0.0) == pytest.approx(1.0 + 1.8 / SPEED, abs=1e-15)
    assert b.tau_at(100.0) == pytest.approx(1.0 + 100.0 / SPEED, abs=1e-15)
