"""The limits a scene's GLI endpoints run into, and which one an ``mq_open`` failure hit.

Every link with the ``mq`` endpoint costs two POSIX queues; Linux bounds them three ways, each with
its own remedy, and ``mq_open`` reports two of them with the same EMFILE:

- the per-user budget ``RLIMIT_MSGQUEUE`` (``ulimit -q``, 819 200 bytes by default): the bytes of all
  the queues a user created, by every one of its processes (EMFILE);
- the system-wide count ``/proc/sys/fs/mqueue/queues_max`` (256 by default), all users together;
  a process with CAP_SYS_RESOURCE (root) is not bound by it (ENOSPC);
- the process's descriptors ``RLIMIT_NOFILE`` (``ulimit -n``): each open queue is one, as is each
  link's Unix socket and each client on it (EMFILE too).

:func:`budget_problems` compares what a scene needs (:func:`scene_need`) with the limits
(:func:`read_limits`) for ``hilgate check``; :func:`open_failure` names the limit an actual failure
hit.  A link with ``gli: [socket]`` needs no queue at all.

The kernel lists every queue only through the mqueue filesystem, which containers and many machines
do not mount at ``/dev/mqueue``.  The queues a scene names are therefore asked about by name through
the queue API (``posix_ipc``: existence, owner, size); how many queues exist on the system, and what
this user's other queues cost, are then unknown, and said to be.
"""

from __future__ import annotations

import errno
import os
import resource
from dataclasses import dataclass
from typing import Iterable

from ..core.packets import packet_class

MAX_MESSAGES = 10
MAX_MESSAGE_SIZE = 8192
QUEUE_OVERHEAD = 96
"""Kernel bookkeeping per message slot (struct msg_msg and a priority-tree node), roughly."""
BASE_DESCRIPTORS = 64
"""Descriptors a daemon holds besides its links' (epoll, pipes, the trace, the control socket, Python's)."""
MQUEUE_DIR = os.environ.get("HILGATE_MQUEUE_DIR", "/dev/mqueue")
"""Where the mqueue filesystem is mounted, if it is (the conventional place; the environment variable
names another, as a test that mounts one in a private mount namespace does)."""
QUEUES_MAX = "/proc/sys/fs/mqueue/queues_max"


def queue_cost(message_size: int, messages: int = MAX_MESSAGES) -> int:
    """Bytes a queue costs its creator's RLIMIT_MSGQUEUE budget."""
    return messages * (message_size + QUEUE_OVERHEAD)


def queue_names(link_id: str) -> tuple[str, str]:
    """(application → hilgate, hilgate → application), dccomms' names."""
    return f"/{link_id}_tx_dlnk_phy", f"/{link_id}_rx_dlnk_phy"


@dataclass(frozen=True)
class Limits:
    """The limits a daemon started now by this user would have (it raises its soft limits to the hard ones)."""

    user_bytes: int | None          # RLIMIT_MSGQUEUE; None: unlimited
    user_bytes_used: int | None     # bytes of queues this user has already; None: unknown (not listed)
    queues_max: int | None          # None: not bound by it (CAP_SYS_RESOURCE) or unknown
    queues_existing: frozenset[str] | None  # names of every queue on the system now; None: unknown
    descriptors: int | None         # RLIMIT_NOFILE; None: unlimited
    present: frozenset[str] = frozenset()  # queues asked about by name that exist (names without '/')
    own_bytes: int = 0              # what those of them that are this user's cost it (known in any case)

    @property
    def listed(self) -> bool:
        """Whether every queue on the system could be listed (the mqueue filesystem is mounted)."""
        return self.queues_existing is not None

    def exists(self, name: str) -> bool:
        name = name.lstrip("/")
        return name in self.present or name in (self.queues_existing or ())


@dataclass(frozen=True)
class Need:
    links: int
    mq_links: int
    new_queues: int      # queues the scene's links would create (those that do not exist yet)
    queue_bytes: int     # what those new queues cost the user's budget
    message_size: int    # the size they would be created at (largest packet class)
    descriptors: int


def scene_need(links: Iterable[tuple[str, tuple[str, ...], str]], limits: Limits) -> Need:
    """What ``links`` (id, gli endpoints, packet class name) need.  Queues are created at dccomms'
    8192 bytes when the user's budget is unlimited, else at the size of each link's packet class
    (:func:`hilgate.gli.queues.plan_message_size`); queues that exist already are reused."""
    links = list(links)
    new_queues = queue_bytes = descriptors = mq_links = 0
    largest = 0
    for link_id, gli, packet in links:
        if "socket" in gli:
            descriptors += 1
        if "mq" not in gli:
            continue
        mq_links += 1
        descriptors += 2
        size = MAX_MESSAGE_SIZE if limits.user_bytes is None else 1 + packet_class(packet).body_size
        largest = max(largest, size)
        for name in queue_names(link_id):
            if not limits.exists(name):
                new_queues += 1
                queue_bytes += queue_cost(size)
    return Need(len(links), mq_links, new_queues, queue_bytes, largest, descriptors + BASE_DESCRIPTORS)


def budget_problems(need: Need, limits: Limits) -> list[str]:
    """One line per limit the scene would run into, naming it and how to raise it (empty: it fits)."""
    problems = []
    used = limits.own_bytes if limits.user_bytes_used is None else limits.user_bytes_used  # unknown: what is known
    existing = len(limits.queues_existing) if limits.queues_existing is not None else 0
    if need.queue_bytes and limits.user_bytes is not None and used + need.queue_bytes > limits.user_bytes:
        in_use = f"{used}" if limits.user_bytes_used is not None else f"at least {used}"
        problems.append(
            f"per-user POSIX queue budget RLIMIT_MSGQUEUE (ulimit -q): {need.new_queues} new queues need "
            f"{need.queue_bytes} bytes, this user has {in_use} in use of {limits.user_bytes}; "
            f"raise it (LimitMSGQUEUE=infinity in the systemd unit, `ulimit -q unlimited`), remove stale queues "
            f"(hilgate queues SCENE --unlink) or give links that need no dccomms application gli: [socket]")
    if need.new_queues and limits.queues_max is not None and existing + need.new_queues > limits.queues_max:
        others = f"{existing} existing" if limits.listed else "those that exist (how many: unknown)"
        problems.append(
            f"system-wide queue count fs.mqueue.queues_max ({QUEUES_MAX}): {need.new_queues} new queues and "
            f"{others} exceed {limits.queues_max} (all users together; ulimit -q "
            f"does not help); raise it (sysctl fs.mqueue.queues_max={existing + need.new_queues}"
            f"), remove stale queues or give links that need no dccomms application gli: [socket]")
    if limits.descriptors is not None and need.descriptors > limits.descriptors:
        problems.append(
            f"open files RLIMIT_NOFILE (ulimit -n): about {need.descriptors} descriptors needed (two per queue "
            f"link, one per socket and client), the hard limit is {limits.descriptors}; raise it (LimitNOFILE= "
            f"in the systemd unit, `ulimit -Hn`)")
    return problems


def describe(need: Need, limits: Limits) -> str:
    """The budget as ``hilgate check`` prints it."""
    if limits.user_bytes is None:
        budget = "unlimited"
    elif limits.user_bytes_used is not None:
        budget = f"{limits.user_bytes} bytes ({limits.user_bytes_used} in use)"
    else:
        budget = f"{limits.user_bytes} bytes (in use: unknown, {limits.own_bytes} by this scene's existing queues)"
    if limits.queues_max is None:
        count = "not binding (CAP_SYS_RESOURCE)"
    else:
        count = f"{limits.queues_max} ({len(limits.queues_existing)} exist)" if limits.listed else \
            f"{limits.queues_max} (how many exist: unknown)"
    files = "unlimited" if limits.descriptors is None else str(limits.descriptors)
    unknown = "" if limits.listed else (f"\n  (unknown: the kernel lists queues only where the mqueue filesystem is "
                                        f"mounted, and {MQUEUE_DIR} is not; this scene's own queues were asked "
                                        f"for by name)")
    return (f"GLI endpoints: {need.mq_links} of {need.links} links with POSIX queues: {need.new_queues} new queues "
            f"of {need.message_size} bytes × {MAX_MESSAGES}, {need.queue_bytes} bytes; per-user budget "
            f"(ulimit -q): {budget}; system-wide queues_max: {count}; descriptors: ~{need.descriptors} of {files}"
            f"{unknown}")


def read_limits(names: Iterable[str] = ()) -> Limits:
    """The limits of a daemon this process would start (soft limits raised to the hard ones).  ``names``
    (a scene's queues) are asked about one by one, so they are known whether or not the mqueue
    filesystem is mounted."""
    hard_bytes = resource.getrlimit(resource.RLIMIT_MSGQUEUE)[1]
    hard_files = resource.getrlimit(resource.RLIMIT_NOFILE)[1]
    existing = list_queues()
    present, own = set(), 0
    for name in dict.fromkeys(name.lstrip("/") for name in names):
        found = probe_queue(name)
        if found is not None:
            present.add(name)
            own += found[1] if found[0] == os.geteuid() else 0
    used = None
    if existing is not None:
        found_all = [probe_queue(name) for name in existing]
        used = sum(found[1] for found in found_all if found is not None and found[0] == os.geteuid())
    return Limits(None if hard_bytes == resource.RLIM_INFINITY else hard_bytes, used,
                  None if _bypasses_queues_max() else _read_int(QUEUES_MAX), existing,
                  None if hard_files == resource.RLIM_INFINITY else hard_files, frozenset(present), own)


def list_queues() -> frozenset[str] | None:
    """Every queue on the system (names without '/'), or None where the kernel does not say: only the
    mqueue filesystem lists them, and it is not mounted everywhere."""
    try:
        if not os.path.ismount(MQUEUE_DIR):
            return None
        return frozenset(os.listdir(MQUEUE_DIR))
    except OSError:
        return None


def probe_queue(name: str) -> tuple[int, int] | None:
    """(owner's uid, what it costs its owner's budget) of the queue ``name``, through the queue API
    alone; None if there is no such queue.  A queue this user may not open is someone else's (uid -1,
    cost unknown, 0).  It is opened read-only and never read from."""
    import posix_ipc

    try:
        queue = posix_ipc.MessageQueue("/" + name.lstrip("/"), read=True, write=False)
    except posix_ipc.ExistentialError:
        return None
    except (posix_ipc.Error, OSError, ValueError):
        return (-1, 0)
    try:
        return os.fstat(queue.mqd).st_uid, queue_cost(queue.max_message_size, queue.max_messages)
    except OSError:
        return (-1, 0)
    finally:
        queue.close()


def _bypasses_queues_max() -> bool:
    """CAP_SYS_RESOURCE in the effective set (bit 24 of CapEff): mq_open then ignores queues_max."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("CapEff:"):
                    return bool(int(line.split()[1], 16) >> 24 & 1)
    except (OSError, ValueError):
        pass
    return os.geteuid() == 0


def _read_int(path: str) -> int | None:
    try:
        with open(path) as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None


def open_failure(name: str, exc: BaseException | None) -> str:
    """The one-line error for a queue that could not be created, naming the limit it hit."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code == errno.ENOSPC or "No space left" in text or "total number of queues" in text:
        return (f"cannot create POSIX queue {name}: the system-wide number of queues is used up "
                f"(fs.mqueue.queues_max = {_read_int(QUEUES_MAX)}, all users together; ulimit -q does not help): "
                f"raise it with `sysctl fs.mqueue.queues_max=N`, remove stale queues (hilgate queues SCENE "
                f"--unlink) or give links that need no dccomms application gli: [socket]")
    if code == errno.EMFILE or "maximum number of files" in text:
        if _descriptors_exhausted():
            return (f"cannot create POSIX queue {name}: this process has as many open files as RLIMIT_NOFILE "
                    f"allows ({resource.getrlimit(resource.RLIMIT_NOFILE)[0]}; each queue is one): raise it with "
                    f"LimitNOFILE= in the systemd unit or `ulimit -n`")
        return (f"cannot create POSIX queue {name}: the queue budget of this user is used up. Each link needs "
                f"two queues and Linux limits their total size per user (RLIMIT_MSGQUEUE, ulimit -q, now "
                f"{resource.getrlimit(resource.RLIMIT_MSGQUEUE)[0]} bytes): raise it with "
                "LimitMSGQUEUE=infinity in the systemd unit or `ulimit -q unlimited`, remove stale queues "
                "(hilgate queues SCENE --unlink) or give links that need no dccomms application gli: [socket].")
    if code == errno.ENFILE or "total number of open files" in text:
        return f"cannot create POSIX queue {name}: the system's open-file table is full (fs.file-max)"
    return f"cannot open POSIX queue {name}: {exc}"


def is_user_budget(exc: BaseException) -> bool:
    """mq_open's EMFILE for RLIMIT_MSGQUEUE, not for the descriptor limit."""
    if "maximum number of files" not in str(exc) and getattr(exc, "errno", None) != errno.EMFILE:
        return False
    return not _descriptors_exhausted()


def _descriptors_exhausted() -> bool:
    try:
        open_fds = len(os.listdir("/proc/self/fd"))
    except OSError:
        return False
    return open_fds >= resource.getrlimit(resource.RLIMIT_NOFILE)[0] - 1
