"""The real-time loop's adaptive spin and linger, driven with given times (no wall-clock bounds)."""

from __future__ import annotations

import pytest

from hilgate.core.realtime import LINGER_FLOOR, RealtimeScheduler


@pytest.fixture
def loop():
    scheduler = RealtimeScheduler()
    scheduler._credit_time = 0.0  # the tests' own clock starts at 0
    yield scheduler
    scheduler.close()


def test_spin_follows_how_late_sleeps_end_within_its_bounds(loop):
    for _ in range(500):
        loop._learn_oversleep(0.00004)  # this host wakes 40 µs late
    assert loop.spin_s == pytest.approx(1.5 * 0.00004 + 0.00002, rel=1e-3)
    loop._learn_oversleep(0.2)  # a preemption: the spin goes to its maximum at once, no further
    assert loop.spin_s == loop.spin_max_s == 0.0003
    for _ in range(2000):
        loop._learn_oversleep(0.0)
    assert loop.spin_s == loop.spin_min_s == 0.00005


def test_linger_halves_on_each_miss_and_grows_when_input_follows_a_sleep(loop):
    loop._last_input = 100.0
    assert loop._linger_now(100.0001)  # within 150 µs of the input: keep polling
    assert not loop._linger_now(100.0002)  # expired with no input: a miss
    assert loop._linger == pytest.approx(0.000075)
    for k in range(3):
        loop._last_input = 200.0 + k
        loop._linger_now(200.0 + k)
        loop._linger_now(200.0 + k + 0.001)
    assert loop._linger == 0.0  # 75 → 37.5 → 18.75 → 9.4 µs < the floor: no linger at all
    loop._last_input = 250.0
    assert not loop._linger_now(250.0 + 1e-9)  # right after an input, but the window is 0
    loop._last_input = 300.0
    loop._input_came(300.00003, after_sleep=True)  # input 30 µs after the loop went to sleep
    assert loop._linger == pytest.approx(max(2 * 0.0, LINGER_FLOOR, 0.00003))
    loop._input_came(300.0003, after_sleep=True)  # 300 µs later: beyond linger_s, no growth
    assert loop._linger == pytest.approx(0.00003)


def test_lingering_stops_when_its_share_of_the_wall_clock_is_spent(loop):
    loop._linger_credit = 0.0
    loop._credit_time = loop._last_input = 400.0
    assert not loop._linger_now(400.00001)  # no credit left: sleep at once
    loop._refill(400.001)  # half of 1 ms of wall clock comes back as credit
    assert loop._linger_credit == pytest.approx(0.0005)
    loop._last_input = 400.001
    assert loop._linger_now(400.00101)  # an input now: polling again


def test_fixed_mode_keeps_the_old_behaviour(loop, monkeypatch):
    monkeypatch.setattr(RealtimeScheduler, "adaptive", False)
    loop._last_input = 10.0
    assert loop._linger_now(10.00014) and not loop._linger_now(10.00016)
    loop._learn_oversleep(0.0)  # never called in fixed mode; the spin stays what it was given
    assert loop.spin_max_s == 0.0003
