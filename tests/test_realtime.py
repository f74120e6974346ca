"""The real-time scheduler: the same model semantics as virtual time, inputs from descriptors,
other threads and signals.  Nothing here asserts speed; order and model times are exact."""

import os
import select
import signal
import socket
import threading

from hilgate.core.realtime import RealtimeScheduler
from hilgate.core.notify import notify


def test_timers_fire_in_order_with_their_exact_model_times():
    clock = RealtimeScheduler()
    seen = []
    for t in (0.03, 0.01, 0.02, 0.02):
        clock.at(t, lambda t=t: seen.append((t, clock.now())))
    clock.run(0.05)
    assert [t for t, _ in seen] == [0.01, 0.02, 0.02, 0.03]
    assert all(t == now for t, now in seen)  # model time is the scheduled time, not the late wall time
    assert clock.now() == 0.05
    clock.close()


def test_readers_posts_from_threads_and_stop():
    clock = RealtimeScheduler()
    left, right = socket.socketpair()
    got = []
    clock.add_reader(left.fileno(), lambda: got.append(left.recv(10)))
    clock.at(0.01, lambda: right.send(b"ping"))
    # the thread starts from the loop, after the ping, so the order holds however late the loop starts
    clock.at(0.02, lambda: threading.Timer(0.03, lambda: clock.post(got.append, "posted")).start())
    clock.at(0.2, clock.stop)
    clock.run()
    assert got == [b"ping", "posted"]
    assert clock.now() >= 0.2  # stopped by the timer at 0.2 (how much later the loop noticed depends on the host)
    clock.close()
    left.close()
    right.close()


def test_model_time_never_goes_back_for_inputs():
    clock = RealtimeScheduler()
    times = []
    left, right = socket.socketpair()
    clock.add_reader(left.fileno(), lambda: (left.recv(10), times.append(clock.now())))
    for i in range(20):
        clock.at(0.002 * i, lambda: (right.send(b"x"), times.append(clock.now())))
    clock.run(0.06)
    assert times == sorted(times)
    clock.close()


def test_speed_scales_model_time():
    import time

    clock = RealtimeScheduler(speed=10.0)
    marks = []

    def mark():
        marks.append((clock.model_time(), time.perf_counter(), clock.model_time()))

    clock.at(0.2, mark)
    clock.at(1.0, mark)
    clock.at(1.0, clock.stop)
    start = time.perf_counter()
    clock.run()
    assert time.perf_counter() - start >= 0.1 - 0.002  # 1 model second is never sooner than 0.1 s of wall clock
    (m1_before, w1, m1_after), (m2_before, w2, m2_after) = marks
    # model time runs at 10 times the wall clock (bounds by the readings around each wall reading)
    assert m2_before - m1_after <= 10 * (w2 - w1) <= m2_after - m1_before
    clock.close()


def test_defer_runs_after_the_events_due_now():
    clock = RealtimeScheduler()
    order = []
    clock.at(0.01, lambda: (order.append("a"), clock.defer(lambda: order.append("deferred"))))
    clock.at(0.01, lambda: order.append("b"))
    clock.run(0.02)
    assert order == ["a", "b", "deferred"]
    clock.close()


def test_signals_are_handled_in_the_loop():
    clock = RealtimeScheduler()
    got = []
    clock.on_signal(signal.SIGUSR1, lambda signum: (got.append(signum), clock.stop()))
    clock.at(0.01, lambda: os.kill(os.getpid(), signal.SIGUSR1))
    clock.run(5.0)
    assert got == [signal.SIGUSR1]
    signal.signal(signal.SIGUSR1, signal.SIG_DFL)
    clock.close()


def test_sd_notify_datagram(tmp_path, monkeypatch):
    path = str(tmp_path / "notify")
    server = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    server.bind(path)
    monkeypatch.setenv("NOTIFY_SOCKET", path)
    assert notify("READY=1", "STATUS=ok")
    assert server.recv(100) == b"READY=1\nSTATUS=ok"
    monkeypatch.delenv("NOTIFY_SOCKET")
    assert not notify("READY=1")
    server.close()


def test_systemd_unit_has_what_operations_need():
    unit = open(os.path.join(os.path.dirname(__file__), "..", "systemd", "hilgate.service")).read()
    lines = {line.split("=", 1)[0]: line.split("=", 1)[1] for line in unit.splitlines()
             if "=" in line and not line.startswith("#")}
    assert lines["Type"] == "notify"
    assert lines["ExecReload"] == "/bin/kill -HUP $MAINPID"
    assert lines["Restart"] == "on-failure"
    assert lines["User"] == "hilgate" and lines["SupplementaryGroups"] == "dialout"
    assert lines["LimitMSGQUEUE"] == "infinity"
    for option in ("NoNewPrivileges", "ProtectSystem", "PrivateTmp", "ProtectHome", "RestrictAddressFamilies"):
        assert option in lines
    env = open(os.path.join(os.path.dirname(__file__), "..", "systemd", "hilgate.env")).read()
    assert "HILGATE_SCENE=" in env and "HILGATE_ARGS=" in env


def test_a_long_wait_is_one_epoll_wait_that_returns_what_is_ready_and_never_waits_past_its_deadline():
    from hilgate.core.ioloop import EPOLL_WAIT_MIN_S, IoLoop

    loop = IoLoop()
    left, right = socket.socketpair()
    loop.add_reader(left.fileno(), lambda: None)
    right.send(b"x")
    for timeout in (0.0005, EPOLL_WAIT_MIN_S, 0.0029, 0.5):  # short (select, then a look) and long (epoll_wait)
        assert loop.wait(timeout) == [(left.fileno(), select.EPOLLIN)]
    left.recv(1)
    assert loop.wait(0.0005) == []
    # how long a wait may sleep: whole milliseconds from EPOLL_WAIT_MIN_S on (never more than asked)
    assert loop.waits_until(0.0005) == 0.0005
    assert loop.waits_until(0.0029) == 0.002 and loop.waits_until(0.5) == 0.5 and loop.waits_until(0.0125) == 0.012
    loop.close()
    left.close()
    right.close()


def test_calls_posted_from_threads_all_run_in_order_however_the_wake_ups_fall():
    """Only the post that finds the queue empty writes a wake-up: none may be lost while the loop sleeps
    in a long wait (no timer before the end), empties the queue, or is woken by an earlier one."""
    clock = RealtimeScheduler()
    got: list[tuple[int, int]] = []
    count = 2000

    finished = []
    lock = threading.Lock()

    def poster(name: int) -> None:
        for i in range(count):
            clock.post(got.append, (name, i))
            if i % 97 == 0:
                threading.Event().wait(0.003)  # now and then the loop goes back to sleep (no timer is set)
        with lock:
            finished.append(name)
            if len(finished) == 2:
                clock.post(clock.stop)  # after every call of both: the loop stops once it has run them

    threads = [threading.Thread(target=poster, args=(name,)) for name in (1, 2)]
    clock.at(0.0, lambda: [thread.start() for thread in threads])
    clock.run(until=90.0)  # (a hang guard: stopped as soon as every call ran)
    for thread in threads:
        thread.join()
    assert len(got) == 2 * count
    for name in (1, 2):
        assert [i for n, i in got if n == name] == list(range(count))
    clock.close()
