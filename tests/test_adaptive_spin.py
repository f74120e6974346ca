"""The real-time loop's wait policy, driven with given times (no wall-clock bounds): the spin before
timers follows how late sleeps end, the linger after inputs adapts and keeps to its share of the clock."""

from __future__ import annotations

import pytest

from hilgate.core.waiting import LINGER_FLOOR, AdaptiveWait


@pytest.fixture
def policy():
    return AdaptiveWait(now=0.0)  # the tests' own clock starts at 0


def test_spin_follows_how_late_sleeps_end_within_its_bounds(policy):
    for _ in range(500):
        policy.overslept(0.00004)  # this host wakes 40 µs late
    assert policy.spin_s == pytest.approx(1.5 * 0.00004 + 0.00002, rel=1e-3)
    policy.overslept(0.2)  # a preemption: the spin goes to its maximum at once, no further
    assert policy.spin_s == policy.spin_max_s == 0.0003
    for _ in range(2000):
        policy.overslept(0.0)
    assert policy.spin_s == policy.spin_min_s == 0.00005


def test_linger_halves_on_each_miss_and_grows_when_input_follows_a_sleep(policy):
    policy.last_input = 100.0
    assert policy.keep_polling(100.0001)  # within 150 µs of the input: keep polling
    assert not policy.keep_polling(100.0002)  # expired with no input: a miss
    assert policy.linger == pytest.approx(0.000075)
    for k in range(3):
        policy.last_input = 200.0 + k
        policy.keep_polling(200.0 + k)
        policy.keep_polling(200.0 + k + 0.001)
    assert policy.linger == 0.0  # 75 → 37.5 → 18.75 → 9.4 µs < the floor: no linger at all
    policy.last_input = 250.0
    assert not policy.keep_polling(250.0 + 1e-9)  # right after an input, but the window is 0
    policy.last_input = 300.0
    policy.input_came(300.00003, after_sleep=True)  # input 30 µs after the loop went to sleep
    assert policy.linger == pytest.approx(max(2 * 0.0, LINGER_FLOOR, 0.00003))
    assert policy.last_input == 300.00003
    policy.input_came(300.0003, after_sleep=True)  # 270 µs later: beyond linger_s, no growth
    assert policy.linger == pytest.approx(0.00003)


def test_lingering_stops_when_its_share_of_the_wall_clock_is_spent(policy):
    policy.credit = 0.0
    policy.credit_time = policy.last_input = 400.0
    assert not policy.keep_polling(400.00001)  # no credit left: sleep at once
    policy.refill(400.001)  # half of 1 ms of wall clock comes back as credit
    assert policy.credit == pytest.approx(0.0005)
    policy.last_input = 400.001
    assert policy.keep_polling(400.00101)  # an input now: polling again


def test_the_real_time_scheduler_asks_the_policy_it_is_given():
    from hilgate.core.realtime import RealtimeScheduler

    given = AdaptiveWait(spin_s=0.001, now=0.0)
    scheduler = RealtimeScheduler(wait=given)
    assert scheduler.wait is given
    scheduler.close()
