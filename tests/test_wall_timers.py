"""Wall-clock timers on a busy machine (issue 36): what a device waits for is reckoned from when it really
started waiting, and a device is not blamed for an answer the machine was too busy to read.

A timer that fires late holds the model clock at its own due time (hilgate.core.realtime); pacing and
timeouts reckoned from that time would make a driver write early (a burst into a modem without flow
control) or give up early.  Each test makes the loop late for certain (a callback that sleeps: the sleep
lasts at least that long on any machine, so nothing here depends on how fast the machine is)."""

import os
import time

from hilgate.core.realtime import RealtimeScheduler


def test_after_wall_in_a_late_timer_counts_from_the_wall_clock_not_from_the_due_time():
    loop = RealtimeScheduler()
    seen = {}

    def busy():
        time.sleep(0.2)  # the loop stands still: the next timer fires at least 0.19 s late

    def late():
        seen["due"], seen["fired"] = loop.now(), loop.model_time()
        loop.after_wall(0.05, paced)

    def paced():
        seen["paced"] = loop.now()
        loop.stop()

    loop.at(0.0, busy)
    loop.at(0.01, late)
    loop.run(until=30)
    loop.close()
    assert seen["fired"] - seen["due"] >= 0.19  # it was late
    assert seen["paced"] >= seen["fired"] + 0.05  # and the pacing is from when it ran, not from when it was due


def test_a_late_timeout_lets_the_answer_that_came_meanwhile_be_read_first():
    """A driver waits 0.1 s for an answer, which comes after 0.05 s; the machine stands still for 0.3 s in
    between.  When the loop runs again both are overdue: the answer (ready since 0.05 s) is read before
    the timeout runs, so the timeout, cancelled by the answer, never says "no answer"."""
    loop = RealtimeScheduler()
    r, w = os.pipe()
    os.set_blocking(r, False)
    events = []
    state = {}

    def answer_read():
        os.read(r, 100)
        events.append("answer")
        loop.cancel(state["timeout"])
        loop.after_wall(0.05, loop.stop)

    def no_answer():
        events.append("timeout")

    def ask():
        state["timeout"] = loop.after_wall(0.1, no_answer)
        loop.at(loop.now() + 0.01, freeze)

    def freeze():
        os.write(w, b"OK\r\n")  # the device answers in time...
        time.sleep(0.3)         # ...but the machine stands still past the timeout before the loop reads it

    loop.add_reader(r, answer_read)
    loop.at(0.0, ask)
    loop.run(until=30)
    loop.remove_reader(r)
    loop.close()
    os.close(r), os.close(w)
    assert events == ["answer"]


class _Line:
    """The S100 driver's serial port reduced to what pacing is about: when each piece was written."""

    up = True

    def __init__(self, clock):
        self.clock, self.writes = clock, []

    def write(self, data):
        self.writes.append((self.clock.now(), len(data)))
        return True

    def close(self):
        pass


def test_the_s100_driver_never_writes_a_frame_while_the_last_piece_is_still_leaving_the_modem():
    """Without flow control each piece is paced at the air bitrate (45 bytes at 1800 bit/s: 0.2 s).  A frame
    sent while the previous frame's last piece is still being paced (an application told READY at once, or
    one with frames queued) waits for that piece's time; it used to be written at once, into a modem still
    holding the last piece (seen under load: 12 bytes and the next 45 written 0.4 ms apart)."""
    from hilgate.core.backend import AppFrame
    from hilgate.core.packets import packet_class
    from hilgate.core.scheduler import VirtualScheduler
    from hilgate.drivers.s100 import S100Backend
    from hilgate.drivers.table import S100Options

    class Driver(S100Backend):
        def _open_port(self, **line):
            self.port = _Line(self.scheduler)

    clock = VirtualScheduler()
    packet = packet_class("vl2b")
    driver = Driver("s", 1, packet, S100Options(port="/dev/null", air_bitrate_bps=1800.0), clock, lambda ev: None)
    driver._on_port(True, None)
    size = max(n for n in range(packet.max_payload + 1) if packet.real_length(n) == 100)

    def frame(i):
        payload = bytes([i]) * size
        return AppFrame(packet.encode(payload, src=1, dst=2), payload, packet, 0, 1, 2, clock.now())

    driver.send(frame(1))
    clock.run(0.41)  # two pieces of 45 written and paced; the third (12 bytes) written at 0.4, paced until ~0.453
    assert [n for _, n in driver.port.writes] == [45, 45, 12] and not driver.idle
    driver.send(frame(2))
    clock.run(5)
    writes = driver.port.writes
    assert [n for _, n in writes] == [45, 45, 12] * 2
    for (t0, n0), (t1, _) in zip(writes, writes[1:]):
        assert t1 - t0 >= n0 * 8 / 1800 - 1e-12
