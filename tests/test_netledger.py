"""The settling of frames between hosts, without a network (hilgate/daemon/netledger.py): a receiver's
reports say what it heard and what never came, and the sender traces, once, every frame a report (or a
daemon's end) shows did not arrive, with its cause.  The daemons doing it across real faults are in
tests/test_host_faults.py."""

import pytest

from hilgate.daemon.netcodec import NetError
from hilgate.daemon.netledger import MAX_RANGES, REPEAT_S, Ledger, Receipts, decode_report, encode_report


def report_of(receipts: Receipts, now: float, wall: float = 0.0, final: bool = False, zid: str = "zB") -> dict | None:
    data = receipts.report("B", zid, now, wall, final)
    return None if data is None else decode_report(data)


class Book:
    """A sender's ledger whose traced frames are kept as (pkt, destination, cause)."""

    def __init__(self):
        self.traced: list[tuple[int, str, str]] = []
        self.ledger = Ledger(lambda src, pkt, size, dst, host, cause: self.traced.append((pkt, dst, cause)))
        self.ledger.alive("B", {"zB"})

    def publish(self, number: int, pkt: int | None = None, targets=("b1",)) -> None:
        self.ledger.published("B", number, "a1", number if pkt is None else pkt, 9, tuple(targets))


def test_a_receiver_reports_heard_numbers_once_their_arrivals_are_over_and_the_gaps_as_never_heard():
    receipts = Receipts("zA", 100)
    for number, end in ((1, 1.0), (2, 1.1), (5, 1.5), (6, 9.0)):   # 3 and 4 never came
        assert receipts.heard_one(number, end)
    assert report_of(receipts, now=0.5) is None                     # nothing over yet
    report = report_of(receipts, now=1.6)
    assert (report["low"], report["upto"], report["missed"], report["stopped"]) == (1, 5, [[3, 4]], [])
    assert report["session"] == "zA" and report["epoch_ns"] == 100 and not report["final"]
    assert report_of(receipts, now=1.7, wall=REPEAT_S / 2) is None  # nothing new: not repeated at once
    assert report_of(receipts, now=1.7, wall=REPEAT_S)["upto"] == 5  # ... but now and then (one may be lost)
    assert not receipts.heard_one(4, 2.0)                           # reported never heard: not to be delivered
    last = report_of(receipts, now=2.0, final=True)                 # the daemon stops; 6 is still arriving
    assert (last["upto"], last["missed"], last["stopped"], last["final"]) == (6, [[3, 4]], [[6, 6]], True)


def test_a_daemon_that_starts_while_the_sender_runs_says_it_heard_nothing_before():
    receipts = Receipts("zA", 100)
    assert receipts.heard_one(40_000_000, 1.0)  # (far past the replay window's jump limit: no matter)
    report = report_of(receipts, now=2.0)
    assert (report["upto"], report["missed"]) == (40_000_000, [[1, 39_999_999]])


def test_a_report_carries_at_most_its_ranges_and_says_from_where():
    receipts = Receipts("zA", 100)
    for i in range(MAX_RANGES + 10):
        receipts.heard_one(2 * i + 1, 0.0)  # every other number missing
    report = report_of(receipts, now=1.0)
    # the oldest ranges were let go: the report covers from just after the last of them (a heard number)
    assert len(report["missed"]) == MAX_RANGES and report["low"] == report["missed"][0][0] - 1
    assert report["missed"][-1] == [2 * (MAX_RANGES + 9), 2 * (MAX_RANGES + 9)]


def test_the_sender_traces_what_a_report_says_never_arrived_and_forgets_the_rest():
    book = Book()
    for number in range(1, 7):
        book.publish(number)
    book.ledger.report("B", {"zid": "zB", "low": 1, "upto": 5, "missed": [[3, 4]], "stopped": [], "final": False})
    assert book.traced == [(3, "b1", "net_lost"), (4, "b1", "net_lost")]
    assert book.ledger.pending() == 1 and book.ledger.counters["net_lost"] == 2
    book.ledger.report("B", {"zid": "zB", "low": 1, "upto": 5, "missed": [[3, 4]], "stopped": [], "final": False})
    assert len(book.traced) == 2  # a repeated report traces nothing twice


def test_a_daemons_last_word_makes_what_it_will_not_hear_host_down():
    book = Book()
    for number in range(1, 5):
        book.publish(number)
    book.ledger.report("B", {"zid": "zB", "low": 1, "upto": 2, "missed": [], "stopped": [[2, 2]], "final": True})
    # 2 was arriving when it stopped; 3 and 4 went out after its last report: it will never hear them
    assert book.traced == [(2, "b1", "host_down"), (3, "b1", "host_down"), (4, "b1", "host_down")]
    book.publish(5)  # its token is not yet seen gone here: the frame is down at once all the same
    assert book.traced[-1] == (5, "b1", "host_down") and book.ledger.pending() == 0


def test_a_killed_daemons_frames_are_unconfirmed_when_its_successor_reports():
    book = Book()
    for number in range(1, 4):
        book.publish(number, targets=("b1", "b2"))  # a broadcast: each of the host's links
    book.ledger.alive("B", set())                   # killed: no last word
    book.ledger.alive("B", {"zB2"})                 # started again
    book.publish(4)
    book.ledger.report("B", {"zid": "zB2", "low": 1, "upto": 4, "missed": [[1, 3]], "stopped": [], "final": False})
    # zB may have delivered 1-3 before it died: nobody can say
    assert book.traced == [(n, link, "unconfirmed") for n in (1, 2, 3) for link in ("b1", "b2")]
    assert book.ledger.pending() == 0


def test_frames_for_a_host_that_is_down_are_traced_at_once_and_the_rest_when_the_sender_stops():
    book = Book()
    book.ledger.down("a1", 7, 9, ("b1",), "B")
    book.publish(1)
    assert book.traced == [(7, "b1", "host_down")]
    book.ledger.close()
    assert book.traced[-1] == (1, "b1", "unconfirmed") and book.ledger.pending() == 0


@pytest.mark.parametrize("mangle", [
    lambda r: {**r, "u": -1}, lambda r: {**r, "m": [[5, 3]]}, lambda r: {**r, "m": [[1, 2]] * (MAX_RANGES + 1)},
    lambda r: {**r, "l": 10, "u": 2}, lambda r: {**r, "h": 7}, lambda r: {**r, "m": [[1, True]]},
    lambda r: {**r, "x": "all"}, lambda r: [r],
])
def test_a_report_out_of_range_is_refused_before_anything_of_it_is_used(mangle):
    import json

    good = json.loads(encode_report("B", "zB", "zA", 100, 1, 5, [[3, 4]], [], False))
    assert decode_report(json.dumps(good).encode())["missed"] == [[3, 4]]
    with pytest.raises(NetError):
        decode_report(json.dumps(mangle(good)).encode())
    with pytest.raises(NetError):
        decode_report(b"{" * 20000)


def test_a_number_far_ahead_settles_nothing_below_it_while_the_hosts_own_go_on():
    """Issue 37 with issue 36's reports: one message numbered far ahead in the host's session (its stolen
    key) must not make the receiver report every number below it as never heard (and refuse them)."""
    from hilgate.daemon.netcodec import ReplayWindow

    receipts = Receipts("zA", 100)
    for number in (1, 2, 3):
        assert receipts.heard_one(number, 1.0)
    far = 3 + ReplayWindow.MAX_JUMP - 1
    assert receipts.heard_one(far, 1.0)                              # (taken: the replay window took it)
    for number in (4, 5, 6):
        assert receipts.heard_one(number, 1.0)                       # the host's next frames: delivered
    assert report_of(receipts, now=2.0)["upto"] == 6 and receipts.missed == []


def test_a_run_far_ahead_that_goes_on_while_the_others_stand_still_is_the_hosts_jump():
    """Numbers did jump (a cut seen by the other hosts, the hand-over's drops): the run that goes on is
    the host's, and what it skipped is reported never heard."""
    from hilgate.daemon.netcodec import ReplayWindow

    receipts = Receipts("zA", 100)
    for number in (1, 2, 3):
        assert receipts.heard_one(number, 1.0)
    jump = 3 + ReplayWindow.WINDOW + 50
    for number in (jump, jump + 1, jump + 2):
        assert receipts.heard_one(number, 1.0)
    report = report_of(receipts, now=2.0)
    assert (report["upto"], report["missed"]) == (jump + 2, [[4, jump - 1]])
    assert not receipts.heard_one(10, 2.0)                           # reported never heard: not delivered


def test_the_hosts_numbers_reaching_a_number_kept_aside_take_it_along():
    from hilgate.daemon.netcodec import ReplayWindow

    receipts = Receipts("zA", 100)
    assert receipts.heard_one(1, 1.0)
    ahead = 1 + ReplayWindow.WINDOW + 10
    assert receipts.heard_one(ahead, 1.0)
    for number in range(2, ahead - 1):                               # ahead - 1 lost on the way
        assert receipts.heard_one(number, 1.0)
    assert len(receipts.aside) == 1                                  # not reached yet
    assert receipts.heard_one(ahead + 1, 1.0)
    assert receipts.aside == []
    report = report_of(receipts, now=2.0)
    assert (report["upto"], report["missed"]) == (ahead + 1, [[ahead - 1, ahead - 1]])
