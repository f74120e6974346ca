"""What a host's stolen key can still do to a network of daemons (issue 37, items 2 and 3), on loopback
with the lab's credentials, as in tests/test_netauth.py: the thief is a bare Zenoh session holding host
B's certificate.

- A flood of 60 kB garbage transmissions under B's name: the daemon that receives it keeps its memory
  within a bound, answers STATUS all along, counts (and traces) what it could not hold, and still hears
  B's honest frames afterwards.
- One forged message (a session a nanosecond newer than B's, an epoch of 2⁶², a number far ahead in B's
  own session): B's later frames are still heard, and so are those of a B restarted after it.

Nothing is timed: every wait is the kit's hang guard.
"""

from __future__ import annotations

import os
import threading
import time

import pytest

from daemon_kit import HANG_GUARD_S, wait_until  # noqa: E402
from hilgate.client import Link  # noqa: E402
from hilgate.daemon import netcodec  # noqa: E402

zenoh = pytest.importorskip("zenoh")

from test_netauth import (Lab, attacker, creds, lab, peers, rss_mb,  # noqa: E402, F401 (creds, lab: fixtures)
                          transmission)

FLOOD_BOUND_MB = 64.0
"""What a flood of transmissions may add to the receiving daemon's memory: Zenoh's queue for the loop and
the hand-over to it hold a few MB each at these sizes; the rest is Python's and Zenoh's working memory."""
GIVE_UP_MB = 1024.0
"""The test stops the flood once the daemon has grown this much (today's daemon grew by gigabytes):
enough to fail, and the machine is shared."""


FLOOD_MESSAGES = 100_000
"""The flood's length: 6 GB of garbage (the issue's 20 s of it held 1.1-1.9 GB in the daemon)."""


def status_answered(runtime: str) -> dict:
    """One STATUS over the control socket, waiting as long as the hang guard for its answer."""
    from hilgate.control_client import Control

    with Control(runtime, timeout=HANG_GUARD_S) as control:
        return control.request({"class": "STATUS"})


def test_a_flood_of_transmissions_with_a_hosts_key_costs_bounded_memory_and_status_answers(lab):
    """With B's key, 100 000 messages of 60 kB of garbage on B's transmission key as fast as Zenoh takes
    them: A answers STATUS all along the flood, its memory stays within the bound, every message is
    counted once with its cause (``damaged`` when read, ``inbox_full`` when the loop's hand-over could
    not hold it, traced with B's name), and B's own frames are heard once the flood stops."""
    A = lab.hosts["A"]
    pid = A.daemon.process.pid
    baseline = rss_mb(pid)
    thief = attacker(lab.ports[0], os.path.join(lab.creds, "hosts", "B"))
    stop, gave_up = threading.Event(), threading.Event()
    sent = [0]
    peak = [baseline]
    # (the format's version first, as anyone who read hilgate's source would write it: the daemon checks
    # the CRC over all 60 kB before it finds the rest garbage, ``damaged``)
    garbage = bytes([netcodec.VERSION]) + os.urandom(60_000 - 1)

    def flood() -> None:
        # (BLOCK: every message reaches the daemon as fast as TCP takes it, none dropped on the way)
        publisher = thief.declare_publisher(f"{lab.prefix}/tx/B/ac", congestion_control=zenoh.CongestionControl.BLOCK)
        while not stop.is_set() and sent[0] < FLOOD_MESSAGES:
            publisher.put(garbage)
            sent[0] += 1

    def watch() -> None:
        while not stop.is_set():
            peak[0] = max(peak[0], rss_mb(pid))
            if peak[0] - baseline > GIVE_UP_MB:
                gave_up.set()
                stop.set()
            time.sleep(0.05)

    threads = [threading.Thread(target=flood), threading.Thread(target=watch)]
    answers = []
    try:
        wait_until(lambda: peers(thief), what="the thief to connect")
        for thread in threads:
            thread.start()
        wait_until(lambda: sent[0] > 2000 or stop.is_set(), what="the flood to start")
        while sent[0] < FLOOD_MESSAGES and not stop.is_set():  # STATUS all along the flood
            answer = status_answered(A.daemon.runtime)
            answers.append(stop.is_set() or sent[0] >= FLOOD_MESSAGES)
        threads[0].join()

        def accounted():  # every message of the flood once: refused as damaged, or not held (inbox_full)
            counters = lab.counters()
            return counters if counters.get("damaged", 0) + counters.get("inbox_full", 0) >= sent[0] else None

        counters = wait_until(accounted, what="every message of the flood counted")
    finally:
        stop.set()
        for thread in threads:
            if thread.is_alive():
                thread.join()
        thief.close()
    assert not gave_up.is_set(), f"the daemon grew from {baseline:.0f} to {peak[0]:.0f} MB: the flood was stopped"
    # (each STATUS was asked while the flood was on; all but the last were answered while it still was)
    assert answers[:-1] and not any(answers[:-1]), f"STATUS answered only once the flood was over: {answers}"
    assert peak[0] - baseline < FLOOD_BOUND_MB, (baseline, peak[0])
    assert counters.get("damaged", 0) + counters.get("inbox_full", 0) == sent[0] == FLOOD_MESSAGES, counters
    with lab.app(lab.a) as la, Link.open(lab.b, runtime_dir=lab.hosts["B"].daemon.runtime) as lb:
        lb.send(b"after the flood", dst=1)
        message = la.recv(timeout=HANG_GUARD_S)
        assert message is not None and message.data == b"after the flood"
    assert A.sees("B") and A.daemon.process.poll() is None
    A.daemon.stop()
    full = [e for e in A.events() if e.get("ev") == "drop" and e.get("cause") == "inbox_full"]
    assert all(e["src"] == "B" and e["link"] == "*" for e in full)
    assert sum(e["n"] for e in full) == counters.get("inbox_full", 0)  # every one traced, with its host
    print(f"transmission flood: {sent[0]} messages of 60 kB; daemon RSS {baseline:.0f} MB -> peak {peak[0]:.0f} MB; "
          f"{answers.count(False)} STATUS answered during it; counters {counters}")


# -- one forged message ------------------------------------------------------------------------------------


def heard_from_b(lab, la, lb, text: bytes) -> None:
    """B's application sends ``text``; A's receives it, or A counts it a replay (then it fails at once)."""
    before = lab.counters().get("replay", 0)
    lb.send(text, dst=1)
    got = []

    def heard():
        message = la.recv(timeout=0.2)
        if message is not None:
            got.append(message.data)
        return text in got or lab.counters().get("replay", 0) > before

    wait_until(heard, what=f"{text!r} at A")
    assert text in got, f"{text!r} refused as a replay: {lab.counters()}"


def capture_b(lab):
    """A session with B's key that hears B's transmissions: (session, decoded transmissions heard)."""
    from hilgate.daemon.netcodec import decode_transmission

    listener = attacker(lab.ports[0], os.path.join(lab.creds, "hosts", "B"))
    heard: list = []
    wait_until(lambda: peers(listener), what="the listener to connect")
    listener.declare_subscriber(f"{lab.prefix}/tx/B/**",
                                lambda s: heard.append(decode_transmission(s.payload.to_bytes())))
    return listener, heard


def forge(lab, la, thief, blob: bytes) -> str:
    """The thief puts ``blob`` on B's transmission key; once A delivered it (a stolen key forges:
    ``"heard"``) or counted it (``"counted"``)."""
    from hilgate.daemon.netcodec import decode_transmission

    text = bytes(decode_transmission(blob).frame.app_frame.payload)
    counted = sum(lab.counters().values())
    thief.put(f"{lab.prefix}/tx/B/ac", blob)
    heard = []

    def taken():
        message = la.recv(timeout=0.2)
        heard.append(message is not None and message.data == text)
        return any(heard) or sum(lab.counters().values()) > counted

    wait_until(taken, what=f"the forged {text!r} heard or counted")
    return "heard" if any(heard) else "counted"


@pytest.mark.parametrize("forgery", ["session 1 ns newer", "epoch 2**62", "number far ahead"])
def test_one_forged_message_with_a_hosts_key_does_not_silence_it(lab, forgery):
    """B is heard; the thief puts one message under B's name; B's next frames are heard all the same."""
    from hilgate.daemon.netcodec import ReplayWindow

    thief = attacker(lab.ports[0], os.path.join(lab.creds, "hosts", "B"))
    listener, heard = capture_b(lab)
    try:
        wait_until(lambda: peers(thief), what="the thief to connect")
        with lab.app(lab.a) as la, Link.open(lab.b, runtime_dir=lab.hosts["B"].daemon.runtime) as lb:
            heard_from_b(lab, la, lb, b"before")
            wait_until(lambda: heard, what="B's transmission overheard")
            genuine = heard[-1]
            if forgery == "session 1 ns newer":
                forged = transmission("B", lab.b, lab.a, b"forged", number=1, session="f0f0",
                                      epoch_ns=genuine.epoch_ns + 1)
            elif forgery == "epoch 2**62":
                forged = transmission("B", lab.b, lab.a, b"forged", number=1, session="f0f0", epoch_ns=2 ** 62)
            else:
                forged = transmission("B", lab.b, lab.a, b"forged", number=genuine.number + ReplayWindow.MAX_JUMP - 1,
                                      session=genuine.session, epoch_ns=genuine.epoch_ns)
            forge(lab, la, thief, forged)
            for i in range(3):
                heard_from_b(lab, la, lb, b"after %d" % i)
    finally:
        thief.close()
        listener.close()
    if forgery == "epoch 2**62":
        assert lab.counters().get("out_of_time") == 1  # an epoch no host can have: refused, and nothing moved


def test_a_restarted_host_is_heard_again_whatever_was_forged_before(lab):
    """With B's key, a session whose epoch is 30 s ahead (later than B's next start) and one of 2⁶²; B
    is restarted after them and is heard."""
    thief = attacker(lab.ports[0], os.path.join(lab.creds, "hosts", "B"))
    try:
        wait_until(lambda: peers(thief), what="the thief to connect")
        with lab.app(lab.a) as la:
            with Link.open(lab.b, runtime_dir=lab.hosts["B"].daemon.runtime) as lb:
                heard_from_b(lab, la, lb, b"first run")
            forge(lab, la, thief, transmission("B", lab.b, lab.a, b"forged ahead", number=5, session="a0a0",
                                               epoch_ns=time.time_ns() + 30_000_000_000))
            forge(lab, la, thief, transmission("B", lab.b, lab.a, b"forged far", number=5, session="b0b0",
                                               epoch_ns=2 ** 62))
            lab.hosts["B"].daemon.close()
            B = lab.start_b(where="B-again")
            with Link.open(lab.b, runtime_dir=B.daemon.runtime) as lb:
                for i in range(3):
                    heard_from_b(lab, la, lb, b"second run %d" % i)
    finally:
        thief.close()
