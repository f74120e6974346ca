"""The GLI over POSIX message queues, byte for byte as dccomms' ``CommsDeviceService`` (PHY side).

For link id X: ``/X_tx_dlnk_phy`` carries application → hilgate, ``/X_rx_dlnk_phy`` hilgate →
application (names from the application's view).  Both sides open with O_CREAT, so start order does
not matter; nobody unlinks them.  A message is one type byte and a body:

    0 FRAME      the fixed buffer of the link's packet class (real packet + 12-byte virtual area)
    1 REQ_STATE  empty: "are you ready?"
    2 CMD_STATE  one byte, 0 BUSY / 1 READY
    3 NOTBUILT   internal to dccomms, ignored

Like dccomms' device side, hilgate says BUSY at start and READY when it is up, BUSY when it accepts
a frame and READY again when the link's FIFO has drained, and answers every REQ_STATE.  Unlike
dccomms it drains stale messages left in both queues by an earlier run, and every frame it cannot
accept (bad CRC, size, preamble, type) is counted and reported, never fatal.

Sends to the application never block the loop.  When its queue is full (the application is busy
for a moment), messages wait in a backlog of ``backlog`` messages that is flushed as soon as the
kernel says the queue has room; only beyond that are frames dropped and counted (``app_full``).
"""

from __future__ import annotations

import logging
import os
import resource
from collections import deque
from typing import Any, Callable

import posix_ipc

from .packets import Decoded, PacketClass, PacketError

log = logging.getLogger(__name__)

FRAME, REQ_STATE, CMD_STATE, NOTBUILT = 0, 1, 2, 3
BUSY, READY = 0, 1
MAX_MESSAGES = 10
MAX_MESSAGE_SIZE = 8192


def queue_names(link_id: str) -> tuple[str, str]:
    """(application → hilgate, hilgate → application)."""
    return f"/{link_id}_tx_dlnk_phy", f"/{link_id}_rx_dlnk_phy"


class QueueError(OSError):
    """A queue could not be opened; the message says what to change."""


def raise_queue_budget() -> None:
    """Lift RLIMIT_MSGQUEUE as far as this process may.  Linux charges every queue to its creator,
    about 82 kB for 10 × 8192 bytes, and the default budget is 819 200 bytes: nine queues, four and
    a half links."""
    soft, hard = resource.getrlimit(resource.RLIMIT_MSGQUEUE)
    for wanted in ((resource.RLIM_INFINITY, resource.RLIM_INFINITY), (hard, hard)):
        if soft == wanted[0]:
            return
        try:
            resource.setrlimit(resource.RLIMIT_MSGQUEUE, wanted)
            return
        except (ValueError, OSError):
            continue


QUEUE_OVERHEAD = 96
"""Kernel bookkeeping per message slot (struct msg_msg and a priority-tree node), roughly."""

_warned = False


def queue_cost(message_size: int) -> int:
    return MAX_MESSAGES * (message_size + QUEUE_OVERHEAD)


def plan_message_size(links: int, needed: list[int]) -> bool:
    """Whether every link can have dccomms' 10 × 8192-byte queues within RLIMIT_MSGQUEUE; if not,
    each link's queues are made just large enough for its packet class (one warning says so)."""
    soft = resource.getrlimit(resource.RLIMIT_MSGQUEUE)[0]
    if soft == resource.RLIM_INFINITY or 2 * links * queue_cost(MAX_MESSAGE_SIZE) <= soft:
        return True
    _warn_compact(soft, f"{links} links need {2 * links * queue_cost(MAX_MESSAGE_SIZE)} bytes of POSIX queues "
                        f"at dccomms' 10 × {MAX_MESSAGE_SIZE} bytes")
    return False


def _warn_compact(limit: int, why: str) -> None:
    global _warned
    if not _warned:
        _warned = True
        log.warning("%s but this user may have %d (ulimit -q); queues are created just large enough for each "
                    "link's packet class instead (dccomms uses an existing queue as it is). Raise LimitMSGQUEUE= "
                    "(systemd) or ulimit -q to get dccomms' default size.", why, limit)


def open_queue(name: str, needed_size: int = MAX_MESSAGE_SIZE, full_size: bool = True) -> posix_ipc.MessageQueue:
    """Open or create a queue that any local user's application can use (mode 0666 whatever the
    umask, as dccomms does with 0777 under umask 0), non-blocking.

    Created at dccomms' 10 × 8192 bytes when ``full_size``, else (or when the user's queue budget is
    exhausted) at the ``needed_size`` of the link's packet class.  An existing queue is used as is."""
    old = os.umask(0)
    sizes = (MAX_MESSAGE_SIZE, needed_size) if full_size else (needed_size,)
    try:
        for size in dict.fromkeys(sizes):
            try:
                queue = posix_ipc.MessageQueue(name, posix_ipc.O_CREAT, mode=0o666, max_messages=MAX_MESSAGES,
                                               max_message_size=size)
                break
            except (posix_ipc.Error, OSError) as exc:
                error = exc
                if size != needed_size:
                    _warn_compact(resource.getrlimit(resource.RLIMIT_MSGQUEUE)[0],
                                  "the POSIX queue budget is exhausted")
        else:
            raise QueueError(f"cannot open POSIX queue {name}: {error}. Each link needs two queues and Linux "
                             f"limits their total size per user (ulimit -q, now "
                             f"{resource.getrlimit(resource.RLIMIT_MSGQUEUE)[0]} bytes): raise it with "
                             "LimitMSGQUEUE=infinity in the systemd unit or `ulimit -q unlimited`, or remove "
                             "stale queues (hilgate queues --unlink SCENE).")
    finally:
        os.umask(old)
    queue.block = False
    return queue


def unlink_queues(link_ids) -> list[str]:
    """Remove the dccomms queues of these links (those that exist); returns their names.  Linux
    charges a queue to its creator until it is unlinked; dccomms never does."""
    removed = []
    for link_id in link_ids:
        for name in queue_names(link_id):
            try:
                posix_ipc.unlink_message_queue(name)
                removed.append(name)
            except posix_ipc.ExistentialError:
                pass
    return removed


def drain(queue: posix_ipc.MessageQueue) -> int:
    count = 0
    while True:
        try:
            queue.receive()
        except posix_ipc.BusyError:
            return count
        count += 1


class MqEndpoint:
    """One link's pair of queues, attached to the real-time scheduler's loop."""

    kind = "mq"

    def __init__(
        self,
        link_id: str,
        packet: PacketClass,
        scheduler: Any,
        on_frame: Callable[[Decoded], Any],
        on_bad: Callable[[str, int], Any],
        is_ready: Callable[[], bool],
        full_size: bool = True,
        backlog: int = 1000,
    ):
        self.link_id = link_id
        self.packet = packet
        self.scheduler = scheduler
        self.on_frame = on_frame
        self.on_bad = on_bad
        self.is_ready = is_ready
        self.from_app_name, self.to_app_name = queue_names(link_id)
        needed = 1 + packet.body_size
        self.from_app = open_queue(self.from_app_name, needed, full_size)
        self.to_app = open_queue(self.to_app_name, needed, full_size)
        stale = drain(self.from_app) + drain(self.to_app)
        if stale:
            log.info("link %s: drained %d stale messages from its queues", link_id, stale)
        self.sent_state: int | None = None
        self.app_full = 0
        self.delivered = 0
        self.backlog_limit = backlog
        self.backlog: deque[bytes] = deque()
        self._send_state(BUSY)
        scheduler.add_reader(self.from_app.mqd, self._readable)

    def start(self) -> None:
        """The backend is up: say READY (dccomms' bridge says it twice; once is enough for its apps)."""
        self.state_changed()

    def state_changed(self) -> None:
        state = READY if self.is_ready() else BUSY
        if state != self.sent_state:
            self._send_state(state)

    def _send_state(self, state: int) -> None:
        if self._put(bytes([CMD_STATE, state])):
            self.sent_state = state  # else the next change (or REQ_STATE) says it again

    def _put(self, message: bytes) -> bool:
        """Send now, or keep in the backlog; False if the backlog is full too."""
        if not self.backlog:
            try:
                self.to_app.send(message)
                return True
            except posix_ipc.BusyError:
                self.scheduler.set_writer(self.to_app.mqd, self._flush)
        if len(self.backlog) >= self.backlog_limit:
            return False
        self.backlog.append(message)
        return True

    def _flush(self) -> None:
        backlog = self.backlog
        while backlog:
            try:
                self.to_app.send(backlog[0])
            except posix_ipc.BusyError:
                return
            backlog.popleft()
        self.scheduler.set_writer(self.to_app.mqd, None)

    def _readable(self) -> None:
        # Bounded: a flood on one queue must not starve the other links' timers.
        for _ in range(MAX_MESSAGES):
            try:
                message, _priority = self.from_app.receive()
            except posix_ipc.BusyError:
                return
            self._handle(message)

    def _handle(self, message: bytes) -> None:
        if not message:
            self.on_bad("size", 0)
            return
        kind = message[0]
        if kind == FRAME:
            try:
                decoded = self.packet.decode_body(message[1:])
            except PacketError as exc:
                self.on_bad(exc.reason, len(message))
                return
            self.on_frame(decoded)
        elif kind == REQ_STATE:
            self._send_state(READY if self.is_ready() else BUSY)
        elif kind == NOTBUILT:
            return
        else:
            self.on_bad("type", len(message))

    def deliver(self, real: bytes, seq: int, src: int, dst: int) -> bool:
        """Hand a received frame to the application; False if its queue and the backlog are full."""
        if self._put(bytes([FRAME]) + self.packet.encode_body(real, seq, src, dst)):
            self.delivered += 1
            return True
        self.app_full += 1
        return False

    def close(self) -> None:
        self.scheduler.set_writer(self.to_app.mqd, None)
        self.scheduler.remove_reader(self.from_app.mqd)
        for queue in (self.from_app, self.to_app):
            try:
                queue.close()
            except posix_ipc.Error:
                pass
