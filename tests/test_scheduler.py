"""One scheduler core for both clocks: fire_due, defer with one meaning (before the clock moves on),
one guard for a failing callback, wall-clock timers."""

import logging
import socket

import pytest

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


def test_peek_skips_cancelled_events_and_fire_due_fires_what_is_due_at_its_time():
    clock = VirtualScheduler()
    fired = []
    gone = clock.at(0.5, fired.append, "cancelled")
    clock.at(1.5, lambda: fired.append(("kept", clock.now())))
    clock.at(2.5, fired.append, "later")
    clock.cancel(gone)
    assert clock.peek() == 1.5
    assert clock.fire_due(2.0) == 1
    assert fired == [("kept", 1.5)] and clock.now() == 1.5 and clock.peek() == 2.5


def test_deferred_calls_run_before_the_clock_moves_on_in_both_clocks():
    """An input's instant ends when the clock moves to a later input or timer: its deferred calls run
    then, as a timer's do in virtual time (and not once the loop gets round to them)."""
    order = []
    virtual = VirtualScheduler()
    virtual.at(1.0, lambda: virtual.defer(lambda: order.append(("deferred", virtual.now()))))
    virtual.at(2.0, lambda: order.append(("next", virtual.now())))
    virtual.run()
    real = RealtimeScheduler()
    real.advance(1.0)  # an input read at 1.0 defers a call…
    real.defer(lambda: order.append(("deferred", real.now())))
    real.at(2.0, lambda: order.append(("next", real.now())))
    real.fire_due(3.0)  # …which runs before the timer at 2.0
    real.close()
    assert order == [("deferred", 1.0), ("next", 2.0)] * 2
    order.clear()
    real = RealtimeScheduler()
    real.advance(1.0)
    real.defer(lambda: order.append(("deferred", real.now())))
    real.advance(1.5)  # the next input, later: the first one's instant is over
    real.close()
    assert order == [("deferred", 1.0)]


def broken():
    raise ValueError("broken")


def test_a_failing_callback_stops_a_virtual_run_where_it_happened():
    clock = VirtualScheduler()
    clock.at(1.0, broken)
    with pytest.raises(ValueError, match="broken"):
        clock.run()


def test_the_daemon_logs_a_failing_callback_once_and_goes_on(caplog):
    """Timers, deferred calls, inputs and posted calls pass one guard, with one message."""
    clock = RealtimeScheduler()
    left, right = socket.socketpair()
    done = []

    def readable():
        left.recv(10)
        broken()

    clock.add_reader(left.fileno(), readable)
    clock.at(0.001, broken)
    clock.at(0.002, lambda: clock.defer(broken))
    clock.at(0.003, lambda: right.send(b"x"))
    clock.at(0.004, lambda: clock.post(broken))
    clock.at(0.05, lambda: (done.append(clock.now()), clock.stop()))
    with caplog.at_level(logging.ERROR, logger="hilgate.core.realtime"):
        clock.run()
    clock.close()
    left.close()
    right.close()
    assert done == [0.05]
    failures = [r for r in caplog.records if r.getMessage().startswith("callback ")]
    assert len(failures) == 4 and {r.getMessage().rsplit(" ", 1)[1] for r in failures} == {"failed"}


def test_wall_clock_timers_scale_with_the_speed_and_not_in_virtual_time():
    virtual = VirtualScheduler()
    assert virtual.after_wall(2.0, lambda: None)[0] == 2.0
    fast = RealtimeScheduler(speed=4.0)
    assert fast.after_wall(2.0, lambda: None)[0] == 8.0  # 2 s of wall clock are 8 model seconds
    fast.close()
