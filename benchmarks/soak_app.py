#!/usr/bin/env python3
"""The applications of one host in the soak (soak.py): one process holding each of its links' socket GLI,
sending numbered frames on each at a steady rate and keeping what it receives, for as long as it runs.

Each link sends ``--rate`` frames a second (phases spread evenly over the links), to its destinations in
turn (``LINK=ADDR,ADDR``); the payload is the link's frame number, padded to ``--size`` bytes.  A link
whose daemon goes away (restarted) is opened again every 0.2 s until it is back: a frame counts as sent
only once ``send`` took it.  SIGUSR1 pauses the sending (receiving goes on), SIGUSR2 resumes it,
SIGTERM ends the process after it wrote its log (``--log``, JSON): every connection (link, when it
opened), every frame sent (link, connection, number, destination address, wall time) and every frame
received (link, source address, number, wall time).  Wall times are ``time.time()``: the daemons'
traces convert to it through their epochs.

    python benchmarks/soak_app.py --runtime DIR --log FILE [--rate 2] [--size 20] LINK=ADDR,ADDR ...
"""

from __future__ import annotations

import argparse
import json
import os
import selectors
import signal
import sys
import time

from hilgate.client import Link

REOPEN_S = 0.2
SEND_TIMEOUT_S = 60.0  # (a daemon that fell far behind reads late; a send that times out costs the connection)


class Sender:
    """One link of this host: its connection (or None while its daemon is away) and its schedule."""

    def __init__(self, link: str, destinations: list[int], phase: float, period: float):
        self.link = link
        self.destinations = destinations
        self.period = period
        self.due = time.monotonic() + phase
        self.connection: Link | None = None
        self.reopen_at = 0.0
        self.number = 0
        self.opened = 0  # connections so far (each to the daemon serving the link then)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runtime", required=True)
    parser.add_argument("--log", required=True)
    parser.add_argument("--rate", type=float, default=2.0, help="frames a second per link")
    parser.add_argument("--size", type=int, default=20, help="payload bytes")
    parser.add_argument("links", nargs="+", help="LINK=ADDR,ADDR: a link and the addresses it sends to, in turn")
    args = parser.parse_args()
    period = 1.0 / args.rate
    senders = []
    for i, spec in enumerate(args.links):
        link, _, addresses = spec.partition("=")
        senders.append(Sender(link, [int(a) for a in addresses.split(",")], period * i / len(args.links), period))
    state = {"sending": True, "running": True}
    signal.signal(signal.SIGUSR1, lambda *_: state.update(sending=False))
    signal.signal(signal.SIGUSR2, lambda *_: state.update(sending=True))
    signal.signal(signal.SIGTERM, lambda *_: state.update(running=False))
    opened: list[tuple[str, int, float]] = []  # link, its connection's number, wall time
    sent: list[tuple[str, int, int, int, float]] = []  # link, connection, number, destination, wall
    got: list[tuple[str, int, int, float]] = []  # link, source address, number, wall
    selector = selectors.DefaultSelector()
    errors = 0

    def take(sender: Sender, connection: Link) -> None:
        """What the daemon wrote to this connection and is there to read."""
        while True:
            message = connection.recv(timeout=1e-6)
            if message is None:
                return
            got.append((sender.link, message.src, int(message.data), time.time()))

    def drop(sender: Sender) -> None:
        nonlocal errors
        errors += 1
        if sender.connection is not None:
            try:
                take(sender, sender.connection)  # (before it goes: frames the daemon delivered are received)
            except Exception:
                pass
            try:
                selector.unregister(sender.connection.sock)
            except (KeyError, ValueError):
                pass
            sender.connection.close()
        sender.connection = None
        sender.reopen_at = time.monotonic() + REOPEN_S

    while state["running"]:
        now = time.monotonic()
        for sender in senders:
            if sender.connection is None and now >= sender.reopen_at:
                try:
                    sender.connection = Link.open(sender.link, runtime_dir=args.runtime)
                except Exception:
                    sender.reopen_at = now + REOPEN_S
                    continue
                opened.append((sender.link, sender.opened, time.time()))
                sender.opened += 1
                selector.register(sender.connection.sock, selectors.EVENT_READ, sender)
                sender.due = max(sender.due, now)
            if sender.connection is not None and state["sending"] and now >= sender.due:
                destination = sender.destinations[sender.number % len(sender.destinations)]
                payload = str(sender.number).encode().ljust(args.size, b" ")
                try:
                    sender.connection.send(payload, dst=destination, timeout=SEND_TIMEOUT_S)
                except Exception:
                    drop(sender)
                    continue
                sent.append((sender.link, sender.opened - 1, sender.number, destination, time.time()))
                sender.number += 1
                sender.due += sender.period
                if sender.due < now - 1.0:  # (paused, or a long stall: never a burst to catch up)
                    sender.due = now
            elif not state["sending"]:
                sender.due = max(sender.due, now)
        wake = min((s.due for s in senders if s.connection is not None), default=now + REOPEN_S)
        for key, _ in selector.select(timeout=max(0.0, min(wake - time.monotonic(), REOPEN_S))):
            sender = key.data
            try:
                take(sender, sender.connection)
            except Exception:
                drop(sender)
    for sender in senders:
        if sender.connection is not None:
            sender.connection.close()
    with open(args.log, "w") as handle:
        json.dump({"opened": opened, "sent": sent, "got": got, "errors": errors}, handle)
    return 0


if __name__ == "__main__":
    sys.exit(main())
