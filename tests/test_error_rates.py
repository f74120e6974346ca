"""Seeded statistical checks of the loss model: one draw per arrival with the PER of its unit.

Each check counts losses over N independent arrivals, a Binomial(N, p).  The tolerance is z standard
deviations, z = 5: a correct model fails with probability < 6e-7 per check, while an off-by-a-unit
PER (bit vs byte) lies tens of deviations away.  The seeds are fixed, so the outcome is reproducible.
"""

import math

import pytest

from hilgate.models.errormodel import ErrorModel
from hilgate.models.medium import Channel
from netkit import Net

Z = 5.0


def binomial_bounds(n: int, p: float) -> tuple[float, float]:
    sigma = math.sqrt(n * p * (1 - p))
    return n * p - Z * sigma, n * p + Z * sigma


@pytest.mark.parametrize("unit,rate,size,distance", [
    ("bit", "1e-3", 20, 100.0),                 # PER = 1 - (1 - 1e-3)^160 = 0.1479
    ("byte", "0.02", 20, 100.0),                # PER = 1 - 0.98^20 = 0.3324
    ("packet", "0.001 * d", 20, 250.0),         # PER = 0.25
    ("bit", "6e-13 * d^13.7", 20, 5.0),         # the S100 at 5 m: 0.3577
])
def test_loss_fraction_matches_the_per(unit, rate, size, distance):
    n = 4000
    model = ErrorModel(unit, rate)
    p = model.per(distance, size)
    net = Net(Channel("ac", 1500.0), seed=11)
    net.modem("a", (0, 0, 0), bitrate_bps=1e5)
    net.modem("b", (distance, 0, 0), error=model)
    lost = net.lost_of("a", "b", n, size)
    assert all(cause == "prop" for *_, cause in net.of("err", "b"))
    low, high = binomial_bounds(n, p)
    assert low <= lost <= high, (lost, n * p)


def test_different_seeds_draw_differently_and_the_same_seed_identically():
    def losses(seed):
        net = Net(seed=seed)
        net.modem("a", (0, 0, 0), bitrate_bps=1e5)
        net.modem("b", (10, 0, 0), error=ErrorModel("packet", "0.5"))
        for i in range(200):
            net.send("a", "b", 10, at=float(i))
        net.run()
        return [frame for _, _, _, frame, _ in net.of("err")]

    assert losses(1) == losses(1)
    assert losses(1) != losses(2)
