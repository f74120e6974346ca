"""The hand-over from other threads to the loop (hilgate/core/inbox.py, issue 37 item 2): bounded per
source in messages and bytes, and in bytes in all; what does not fit is counted per source and never
copied; the loop takes a bounded batch per turn, one message of each source in turn.  And the loop
itself (hilgate/core/realtime.py) runs, each round, only the calls posted before it: a call that keeps
posting itself does not keep the loop from its descriptors."""

from __future__ import annotations

import socket

from hilgate.core.inbox import OTHERS, Inbox
from hilgate.core.realtime import RealtimeScheduler


class Loop:
    """The posted calls, run when the test says (the loop's part, by hand)."""

    def __init__(self):
        self.posted = []

    def post(self, fn, *args):
        self.posted.append((fn, args))

    def turn(self) -> None:
        calls, self.posted = self.posted, []
        for fn, args in calls:
            fn(*args)


def test_each_source_is_bounded_in_messages_and_bytes_and_its_drops_are_its_own():
    loop, batches = Loop(), []
    inbox = Inbox(loop.post, lambda items, dropped: batches.append((items, dropped)), limit=3, max_bytes=100,
                  total_bytes=140)
    assert [inbox.put(f"a{i}", 10, "A") for i in range(5)] == [True, True, True, False, False]  # 3 messages
    assert inbox.put("b0", 60, "B") and not inbox.put("b1", 60, "B")  # 120 bytes > 100
    assert not inbox.put("c0", 60, "C")  # 30 + 60 + 60 > 140 in all
    assert len(loop.posted) == 1  # one wake-up for all of it
    loop.turn()
    assert batches == [(["a0", "b0", "a1", "a2"], {"A": 2, "B": 1, "C": 1})]  # in turns, each source in order
    assert inbox.put("a5", 10, "A") and len(loop.posted) == 1  # room again, and a new wake-up


def test_a_message_that_does_not_fit_is_never_copied():
    loop, made = Loop(), []
    inbox = Inbox(loop.post, lambda items, dropped: None, limit=1)

    def make(item):
        made.append(item)
        return item.upper()

    assert inbox.put("x", 1, "A", make) and not inbox.put("y", 1, "A", make)
    assert made == ["x"]


def test_the_loop_takes_a_batch_per_turn_and_the_flood_waits_its_turns():
    loop, batches = Loop(), []
    inbox = Inbox(loop.post, lambda items, dropped: batches.append(items), limit=10_000, batch=4)
    for i in range(10):
        inbox.put(("flood", i), source="F")
    inbox.put(("honest", 0), source="H")
    inbox.put(("honest", 1), source="H")
    loop.turn()  # one batch, then the drain posts itself again: the loop's other inputs come in between
    assert batches == [[("flood", 0), ("honest", 0), ("flood", 1), ("honest", 1)]]
    assert len(loop.posted) == 1
    loop.turn()
    loop.turn()
    assert batches[1:] == [[("flood", i) for i in range(2, 6)], [("flood", i) for i in range(6, 10)]]
    assert loop.posted == []  # nothing left: no more wake-ups until something comes


def test_drops_of_more_sources_than_it_keeps_are_counted_together():
    loop, batches = Loop(), []
    inbox = Inbox(loop.post, lambda items, dropped: batches.append(dropped), limit=0, max_sources=2)
    for source in ("a", "b", "c", "d"):
        inbox.put("x", source=source)
    loop.turn()
    assert batches == [{"a": 1, "b": 1, OTHERS: 2}]


def test_a_call_that_keeps_posting_itself_leaves_the_loop_its_descriptors():
    """A flood's hand-over posts itself again after each batch; the loop must still read a socket meanwhile
    (before issue 37 it ran posted calls until none was left: the socket was read only after the flood)."""
    clock = RealtimeScheduler()
    ours, theirs = socket.socketpair()
    ours.setblocking(False)
    calls = [0]
    read_after: list[int] = []

    def again() -> None:
        calls[0] += 1
        if calls[0] == 2:
            theirs.send(b"STATUS")  # (a control client's request, once the flood runs)
        if calls[0] < 100_000 and not read_after:
            clock.post(again)
        else:
            clock.stop()

    def readable() -> None:
        ours.recv(100)
        read_after.append(calls[0])

    clock.add_reader(ours.fileno(), readable)
    clock.at(0.0, lambda: clock.post(again))
    clock.run(until=90.0)  # (a hang guard)
    clock.close()
    ours.close()
    theirs.close()
    assert read_after and read_after[0] < 10, read_after
