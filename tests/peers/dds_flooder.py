#!/usr/bin/env python3
"""A hostile ROS 2 node: a DDS participant of its own (another process, as an attacker's would be) with
``--writers`` writers of one link's ``send`` topic, each writing frames as fast as it can or at ``--rate``
frames a second in all, until its standard input closes.

Prints ``matched`` once every writer sees hilgate's reader (``no reader`` and exits 1 if none comes
within the tests' hang guard), then nothing; the frames it sends are
``dst`` 2 and ``F`` bytes, so a test tells them from an honest node's.

    dds_flooder.py DOMAIN TOPIC [--writers N] [--rate HZ] [--size B]
"""

import argparse
import os
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from cyclonedds.pub import DataWriter  # noqa: E402

from hilgate.ros2.idl import message_class  # noqa: E402
from hilgate.ros2.participant import DDSException, Participant, qos  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("domain", type=int)
    parser.add_argument("topic")
    parser.add_argument("--writers", type=int, default=1)
    parser.add_argument("--rate", type=float, default=0.0, help="frames a second in all (0: as fast as it can)")
    parser.add_argument("--size", type=int, default=20)
    args = parser.parse_args()
    node = Participant(args.domain)
    Frame = message_class("hilgate_msgs/msg/Frame")
    topic = node._topic(args.topic, "hilgate_msgs/msg/Frame")
    writers = [DataWriter(node.participant, topic, qos=qos("hilgate_msgs/msg/Frame", "reliable", depth=100))
               for _ in range(args.writers)]
    deadline = time.monotonic() + 90.0  # (the tests' hang guard: no reader, no flood)
    while not all(w.get_publication_matched_status().current_count for w in writers):
        if time.monotonic() > deadline:
            print("no reader", flush=True)
            os._exit(1)
        time.sleep(0.02)
    print("matched", flush=True)
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    frame = Frame(dst=2, data=b"F" * args.size)
    period = len(writers) / args.rate if args.rate else 0.0
    next_at = time.monotonic()
    while not stop.is_set():
        for writer in writers:
            try:
                writer.write(frame)
            except DDSException:  # its history full of frames hilgate has not acknowledged: on to the next
                pass
        if period:
            next_at += period
            delay = next_at - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_at = time.monotonic()
    os._exit(0)  # (not Cyclone's orderly teardown: the test has what it needs)


if __name__ == "__main__":
    main()
