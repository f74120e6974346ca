"""One scheduler core for both clocks: peek/step, defer with one meaning, wall-clock timers."""

from hilgate.core.realtime import RealtimeScheduler
from hilgate.core.scheduler import VirtualScheduler


def test_defer_runs_after_the_events_of_the_same_instant_in_virtual_time_too():
    clock = VirtualScheduler()
    order = []
    clock.at(1.0, lambda: (order.append("a"), clock.defer(lambda: order.append(("deferred", clock.now())))))
    clock.at(1.0, lambda: order.append("b"))
    clock.at(2.0, lambda: order.append("c"))
    clock.run()
    assert order == ["a", "b", ("deferred", 1.0), "c"]


def test_peek_skips_cancelled_events_and_step_fires_the_next_at_its_time():
    clock = VirtualScheduler()
    fired = []
    gone = clock.at(0.5, fired.append, "cancelled")
    clock.at(1.5, fired.append, "kept")
    clock.cancel(gone)
    assert clock.peek() == 1.5
    clock.step()
    assert fired == ["kept"] and clock.now() == 1.5 and clock.peek() == float("inf")


def test_wall_clock_timers_scale_with_the_speed_and_not_in_virtual_time():
    virtual = VirtualScheduler()
    assert virtual.after_wall(2.0, lambda: None)[0] == 2.0
    fast = RealtimeScheduler(speed=4.0)
    assert fast.after_wall(2.0, lambda: None)[0] == 8.0  # 2 s of wall clock are 8 model seconds
    fast.close()
