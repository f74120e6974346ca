"""The GLI over POSIX message queues, byte for byte as dccomms' ``CommsDeviceService`` (PHY side);
the protocol itself, without queues, is :mod:`hilgate.gli.queue_protocol`.

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
import pwd
import resource
from collections import deque
from typing import Any

import posix_ipc

from ..core.backend import AppFrame
from ..core.endpoint import ABSENT, KEPT, TAKEN, LinkPort
from ..core.packets import PacketClass, PacketError
from .limits import MAX_MESSAGE_SIZE, MAX_MESSAGES, is_user_budget, open_failure, queue_cost, queue_names
from .queue_protocol import FRAME, FrameIn, Ignored, QueueProtocol, Refused, StateRequest

log = logging.getLogger(__name__)



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


_warned = False


def plan_message_size(links: int) -> bool:
    """Whether the links' queues get dccomms' 10 × 8192 bytes (only when this user's queue budget is
    unlimited, as the systemd unit makes it) or just what the link's packet class needs.

    The budget (``ulimit -q``, 819 200 bytes by default) is shared by every process of the user: the
    user's own daemon, a test run, a second daemon on another scene, dccomms applications.  Queues the
    size of what they carry (a vl2b queue is about 21 KB instead of 83 KB) let four times as many links
    share it; a dccomms application uses an existing queue as it is."""
    soft = resource.getrlimit(resource.RLIMIT_MSGQUEUE)[0]
    if soft == resource.RLIM_INFINITY:
        return True
    full = 2 * links * queue_cost(MAX_MESSAGE_SIZE)
    if full > soft:  # said only where it matters: dccomms' size would not even fit an empty budget
        _note_compact(soft, f"{links} links at dccomms' 10 × {MAX_MESSAGE_SIZE} bytes would need {full}")
    return False


def _note_compact(limit: int, why: str) -> None:
    global _warned
    if not _warned:
        _warned = True
        log.info("POSIX queues are sized for each link's packet class: %s of this user's %d-byte queue budget "
                 "(ulimit -q; LimitMSGQUEUE=infinity, as in the systemd unit, gives dccomms' size)", why, limit)


def open_queue(name: str, needed_size: int = MAX_MESSAGE_SIZE, full_size: bool = True,
               group: int | None = None, remedy: str = "hilgate queues SCENE --unlink") -> posix_ipc.MessageQueue:
    """Open or create one of a link's queues, non-blocking, mode 0660 for hilgate's group.

    dccomms opens its queues as the application's user; that user must be in the daemon's group
    (``hilgate`` under systemd) to reach them, as for the sockets.  A queue that exists already is
    checked before it is used: it must belong to the daemon's user (anyone else who created it
    first could read every frame, or refuse them) and carry whole frames of the link's packet class.
    Anything else is refused in one line that says what is wrong and how to remove it (``remedy``).

    Created at dccomms' 10 × 8192 bytes when ``full_size``, else (or when the user's queue budget is
    exhausted) at the ``needed_size`` of the link's packet class."""
    while True:
        try:
            queue = posix_ipc.MessageQueue(name)
        except posix_ipc.ExistentialError:
            queue = _create_queue(name, needed_size, full_size)
            if queue is None:
                continue  # someone created it in between: check theirs
        except posix_ipc.PermissionsError:
            raise QueueError(f"POSIX queue {name} exists but hilgate may not open it (created by another user "
                             f"with a mode that excludes hilgate's); remove it: {remedy}") from None
        except OSError as exc:
            raise QueueError(open_failure(name, exc)) from None
        break
    try:
        _check_queue(name, queue, needed_size, group, remedy)
    except QueueError:
        queue.close()
        raise
    queue.block = False
    return queue


def _create_queue(name: str, needed_size: int, full_size: bool) -> posix_ipc.MessageQueue | None:
    old = os.umask(0o007)
    sizes = (MAX_MESSAGE_SIZE, needed_size) if full_size else (needed_size,)
    error: BaseException | None = None
    try:
        for size in dict.fromkeys(sizes):
            try:
                queue = posix_ipc.MessageQueue(name, posix_ipc.O_CREX, mode=0o660, max_messages=MAX_MESSAGES,
                                               max_message_size=size)
                _created.append(name)
                return queue
            except posix_ipc.ExistentialError:
                return None
            except (posix_ipc.Error, OSError) as exc:
                error = exc
                if size != needed_size and is_user_budget(exc):
                    _note_compact(resource.getrlimit(resource.RLIMIT_MSGQUEUE)[0],
                                  f"a queue at dccomms' 10 × {MAX_MESSAGE_SIZE} bytes no longer fits in what "
                                  f"is left")
    finally:
        os.umask(old)
    raise QueueError(open_failure(name, error))


def _check_queue(name: str, queue: posix_ipc.MessageQueue, needed_size: int, group: int | None,
                 remedy: str) -> None:
    info = os.fstat(queue.mqd)
    if info.st_uid != os.geteuid():
        raise QueueError(f"POSIX queue {name} belongs to {_user(info.st_uid)}, not to hilgate's user "
                         f"{_user(os.geteuid())}: another program created it first; remove it (as its owner "
                         f"or root): {remedy}")
    if queue.max_message_size < needed_size:
        raise QueueError(f"POSIX queue {name} holds messages of at most {queue.max_message_size} bytes but the "
                         f"link's packet class needs {needed_size}; remove it: {remedy}")
    if queue.max_messages < 1:  # pragma: no cover - the kernel refuses 0
        raise QueueError(f"POSIX queue {name} holds no message; remove it: {remedy}")
    # ours: make sure nobody outside the group can read frames, whoever created it with 0666 before
    if info.st_mode & 0o007 or (group is not None and info.st_gid != group):
        try:
            os.fchmod(queue.mqd, 0o660)
            if group is not None and info.st_gid != group:
                os.fchown(queue.mqd, -1, group)
        except OSError as exc:
            raise QueueError(f"POSIX queue {name}: cannot restrict it to hilgate's group: {exc}") from None


def _user(uid: int) -> str:
    try:
        return f"user {pwd.getpwuid(uid).pw_name} (uid {uid})"
    except KeyError:
        return f"uid {uid}"


_created: list[str] = []
"""Queues this process created (not opened): a daemon that fails to start removes them again."""


def unlink_created() -> list[str]:
    """Remove the queues this process created, for a daemon that failed to start: Linux charges them to
    the user until they are unlinked, and no application can be using queues made a moment ago by a
    daemon that never said READY.  (A running daemon never unlinks: applications may hold them.)"""
    removed = []
    while _created:
        name = _created.pop()
        try:
            posix_ipc.unlink_message_queue(name)
            removed.append(name)
        except posix_ipc.Error:
            pass
    return removed


def forget_created() -> None:
    """The daemon is up: the queues it made are the applications' now."""
    _created.clear()


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


def drain(queue: posix_ipc.MessageQueue, limit: int = 100_000) -> list[bytes]:
    """Take every message waiting in ``queue`` (an earlier run's leftovers)."""
    messages = []
    while len(messages) < limit:
        try:
            message, _priority = queue.receive()
        except posix_ipc.BusyError:
            break
        messages.append(message)
    return messages


UNATTENDED_BACKLOG = 64
"""Frames held for a link's queue before any application has shown itself on it: enough for a burst
while a listener starts, little memory for the many links nobody opens.  They are held in the daemon,
not in the queue: dccomms empties its input queue when it starts (``CommsDeviceService::Init`` →
``ClearInputQueue``), then says REQ_STATE, and only then are they put in the queue."""


class MqEndpoint:
    """One link's pair of queues, attached to the real-time scheduler's loop: an endpoint of the link.

    Whether an application is there is known once it speaks (:class:`QueueProtocol`), or once it
    takes messages from its queue (an application that only listens).  Until then frames are held in
    the daemon (at most :data:`UNATTENDED_BACKLOG`) for an application that starts late, and put in
    its queue when it shows itself: a dccomms application empties its queue as it starts, so frames
    already in it would be lost.  What does not fit is not an application's loss but a frame nobody
    was there to read (see :meth:`deliver`).
    Frames that an application left in the queues while no daemon ran are drained at start and
    reported (``stale``), never sent on air."""

    kind = "mq"
    busy = False
    assumes_busy = True  # dccomms' WritePacket: QueueProtocol.receive notes BUSY as said with each frame
    phy = None  # (no PHY reports: hilgate.core.endpoint.Endpoint.phy)

    def __init__(self, port: LinkPort, scheduler: Any, full_size: bool = True, backlog: int = 1000,
                 group: int | None = None):
        self.port = port
        self.scheduler = scheduler
        self.protocol = QueueProtocol(port.packet)
        self.from_app_name, self.to_app_name = queue_names(port.id)
        needed = 1 + port.packet.body_size
        self.from_app = open_queue(self.from_app_name, needed, full_size, group)
        try:
            self.to_app = open_queue(self.to_app_name, needed, full_size, group)
        except BaseException:
            self.from_app.close()
            raise
        self.stale = 0
        for origin, queue in (("app", self.from_app), ("medium", self.to_app)):
            for message in drain(queue):
                if message[:1] == bytes([FRAME]):
                    self.stale += 1
                    port.lost("stale", len(message), src=origin)
                elif origin == "app":
                    self.protocol.attended = True  # its REQ_STATE came before the daemon: it is there
        if self.stale:
            log.warning("link %s: %d stale frames left in its queues while no daemon ran were dropped",
                        port.id, self.stale)
        self.backlog_limit = backlog
        self.backlog: deque[bytes] = deque()
        self.held: list[AppFrame] = []  # frames for an application that has not shown itself yet
        self._queued = 0  # messages put in the application's queue since it was last looked at
        self._tell(self.protocol.state_message(False))  # BUSY until the link is up
        scheduler.add_reader(self.from_app.mqd, self._readable)

    @property
    def attended(self) -> bool:
        return self.protocol.attended

    def set_packet(self, packet: PacketClass) -> None:
        """A reload changed the link's packet class."""
        self.protocol.packet = packet

    # -- application → link --------------------------------------------------------------------

    def _readable(self) -> None:
        # Bounded: a flood on one queue must not starve the other links' timers.  The queue's count
        # says when it is empty: a receive that fails costs as much as a send and a receive together.
        # Every message waiting is taken in this one call, at one instant, so that a burst costs one
        # announcement (one READY), not one per frame: taking one message per call and trusting epoll's
        # level-triggered state for the rest (no mq_getsetattr) was tried in issue 31: each frame became
        # an instant with its own READY, and one link carried 10-12 000 frames/s flat out, not 18-27 000.
        queue = self.from_app
        for _ in range(MAX_MESSAGES):
            try:
                message, _priority = queue.receive()
            except posix_ipc.BusyError:
                return
            self._handle(message)
            try:
                if not queue.current_messages:
                    return
            except posix_ipc.Error:  # closed while handling (a reload removed the link)
                return

    def _handle(self, message: bytes) -> None:
        event = self.protocol.receive(message)
        if self.held:  # the application's first word (dccomms: REQ_STATE, after emptying its queue)
            self._release()
        match event:
            case FrameIn(decoded=decoded):
                try:
                    self.port.send_decoded(decoded, self)  # (the link's send says its state changed, if anyone is to be told)
                except PacketError as exc:
                    log.warning("link %s: %s", self.port.id, exc)
                    self.port.lost(exc.reason, len(decoded.real), src="app")
                    self.port.state_changed()  # the application thinks BUSY now: it is told READY when free
            case StateRequest():
                self._tell(self.protocol.state_message(self.port.ready))
            case Refused(reason=reason, size=size):
                self.port.lost(reason, size, src="app")
                self.port.state_changed()
            case Ignored():
                pass

    # -- link → application (the endpoint) -----------------------------------------------------

    def state(self, ready: bool) -> None:
        protocol = self.protocol
        message = protocol.state_change(ready)
        if message is not None and self._put(message):  # (_tell written out: every READY passes here)
            protocol.said = message[1]  # (protocol.told, written out)

    def _tell(self, message: bytes) -> None:
        if self._put(message):
            self.protocol.told(message)  # else the next change (or REQ_STATE) says it again

    def deliver(self, frame: AppFrame, t: float) -> str:
        """Hand a received frame to the application: ``taken`` (in its queue, or the backlog while it is
        slow to read) or ``app_full`` (the queue and the backlog are full).  Before any application has
        shown itself, the frame is ``kept`` for one that starts late (held in the daemon, at most
        :data:`UNATTENDED_BACKLOG`: nobody may ever come), or is ``absent``."""
        message = self.protocol.message_of(frame)
        if message is None:
            return "size"
        if not self.protocol.attended and self._someone_reads():
            self.protocol.attended = True  # an application that only reads: it took what was queued
        if not self.protocol.attended:
            if len(self.held) >= UNATTENDED_BACKLOG:
                return ABSENT
            self.held.append(frame)
            return KEPT
        if self.held:
            self._release()
        return TAKEN if self._put(message) else "app_full"

    def _release(self) -> None:
        """The application has shown itself: the frames held for it go to its queue, oldest first (one
        that no longer fits, after a reload changed the class, or finds the backlog full is counted)."""
        held, self.held = self.held, []
        for frame in held:
            message = self.protocol.message_of(frame)
            if message is None:
                self.port.lost("size", len(frame.real))
            elif not self._put(message):
                self.port.lost("app_full", len(frame.real))

    def _someone_reads(self) -> bool:
        """Whether messages this endpoint put in the application's queue have been taken since it last
        looked: an application that never writes (a pure listener) shows itself that way."""
        try:
            waiting = self.to_app.current_messages
        except (posix_ipc.Error, OSError):
            return False
        taken = waiting < self._queued
        self._queued = waiting
        return taken

    def _put(self, message: bytes) -> bool:
        """Send now, or keep in the backlog (at most ``--gli-backlog`` messages); False if the backlog
        is full too."""
        if not self.backlog:
            try:
                self.to_app.send(message)
                self._queued += 1
                return True
            except posix_ipc.BusyError:
                self.scheduler.set_writer(self.to_app.mqd, self._flush)
            except (ValueError, posix_ipc.Error, OSError) as exc:  # checked at open; kept for safety
                log.warning("link %s: cannot write %s: %s", self.port.id, self.to_app_name, exc)
                return False
        if len(self.backlog) >= self.backlog_limit:
            return False
        self.backlog.append(message)
        return True

    def _flush(self) -> None:
        backlog = self.backlog
        while backlog:
            try:
                self.to_app.send(backlog[0])
                self._queued += 1
            except posix_ipc.BusyError:
                return
            except (ValueError, posix_ipc.Error, OSError) as exc:
                log.warning("link %s: cannot write %s: %s", self.port.id, self.to_app_name, exc)
            backlog.popleft()
        self.scheduler.set_writer(self.to_app.mqd, None)

    def close(self) -> None:
        self.scheduler.set_writer(self.to_app.mqd, None)
        self.scheduler.remove_reader(self.from_app.mqd)
        for queue in (self.from_app, self.to_app):
            try:
                queue.close()
            except posix_ipc.Error:
                pass


class QueueDoor:
    """Opens each link's dccomms queues (sized once for all links: see :func:`plan_message_size`)."""

    def __init__(self, scheduler: Any, full_size: bool, backlog: int = 1000, group: int | None = None):
        self.scheduler = scheduler
        self.full_size = full_size
        self.backlog = backlog
        self.group = group

    def open(self, port: LinkPort) -> MqEndpoint | None:
        """The link's queues, unless its ``gli:`` leaves them out (then it costs no queue at all)."""
        if "mq" not in port.gli:
            return None
        endpoint = MqEndpoint(port, self.scheduler, self.full_size, self.backlog, self.group)
        port.attach(endpoint)
        return endpoint

    def update(self, handle: MqEndpoint | None, port: LinkPort) -> MqEndpoint | None:
        if handle is None:
            return self.open(port)
        if "mq" not in port.gli:  # a reload took the queues away: closed, not unlinked (an application may hold them)
            port.detach(handle)
            handle.close()
            return None
        handle.set_packet(port.packet)
        return handle

    def close(self, handle: MqEndpoint | None) -> None:
        if handle is not None:
            handle.close()
