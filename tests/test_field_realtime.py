"""Real time without back-dating: a daemon that was preempted stamps late input when it reads it,
after the timers that were already due, and says in the trace how late it was.

The preemption is made deterministic with SIGSTOP/SIGCONT (what a loaded host does to a normal
process for milliseconds, stretched to seconds so that no timing of this machine matters).
"""

import os
import signal
import time

from daemon_kit import quick_scene, unique
from hilgate.client import Link

# 250 bit/s: a 55-byte payload is a 60-byte VariableLength2BPacket, 1.92 s on air; 15 m at
# 1500 m/s is 10 ms of propagation.
AIRTIME = 60 * 8 / 250.0


def test_input_read_after_a_preemption_is_not_back_dated_into_a_collision(daemon_of):
    a, b = unique("a"), unique("b")
    daemon = daemon_of(quick_scene("backdating", a, b, distance_m=15, bitrate_bps=250), [a, b])
    try:
        with Link.open(a, runtime_dir=daemon.runtime) as link_a, Link.open(b, runtime_dir=daemon.runtime) as link_b:
            link_a.send(b"A" * 55, dst=2)
            deadline = time.monotonic() + 30
            while daemon.link_status(a)["tx_packets"] < 1:  # the daemon has read it and put it on air
                assert time.monotonic() < deadline, daemon.output()
                time.sleep(0.005)
            time.sleep(0.2)  # the daemon is back waiting in its loop (A's frame is on air for 1.92 s)
            os.kill(daemon.process.pid, signal.SIGSTOP)  # preempted while A's frame is on air
            try:
                time.sleep(AIRTIME + 0.5)  # A's frame has arrived at B by now (in the model)
                link_b.send(b"B" * 10, dst=1)  # B answers after it: waits in the socket
                time.sleep(0.1)
            finally:
                os.kill(daemon.process.pid, signal.SIGCONT)
            got_b = link_b.recv(timeout=30)
            got_a = link_a.recv(timeout=30)
        assert got_b is not None and got_b.data == b"A" * 55
        assert got_a is not None and got_a.data == b"B" * 10
    finally:
        daemon.stop()
        events = daemon.trace_events()
    assert not [e for e in events if e.get("ev") == "err"], events
    a_rx = next(e for e in events if e["ev"] == "rx" and e["link"] == b)
    b_enq = next(e for e in events if e["ev"] == "enq" and e["link"] == b)
    assert b_enq["t"] >= a_rx["t"]  # stamped when read, after A's frame had arrived
    assert b_enq.get("lateness_s", 0) > 0, b_enq  # and the trace says that the stamp is late
