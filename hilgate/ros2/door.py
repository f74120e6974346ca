"""ROS 2 nodes as link applications: a link whose ``gli:`` names ``ros2`` has three topics under the
scene's namespace (``<ns>/<link>/…``, the link id made a ROS name by :func:`hilgate.scene.ros2.ros_token`):

==========  =========================  ========================================================
topic       type                       who publishes, what
==========  =========================  ========================================================
``send``    ``hilgate_msgs/msg/Frame`` a node: ``dst`` (255 broadcast) and ``data``; the other
                                       fields are ignored (the link's own address is the source)
``recv``    ``hilgate_msgs/msg/Frame`` hilgate: every frame the link receives, with ``src``,
                                       ``dst``, ``model_time`` (s) and ``stamp`` (wall clock)
``ready``   ``std_msgs/msg/Bool``      hilgate: READY (true) or BUSY, when it changes; transient
                                       local, so a node that starts late gets the current one
==========  =========================  ========================================================

``send`` and ``recv`` are reliable unless ``ros2.links.reliability`` says ``best_effort``.

**Bounded per node**, as the Zenoh door is per client (:mod:`hilgate.gli.zenoh_door`): Cyclone DDS
calls :meth:`Ros2Endpoint._on_send` on its own thread; it takes every sample there, each node (a DDS
participant: a ROS 2 process) has its own queue at the door, filled at most at the Zenoh door's rate,
and the loop takes one frame of each node in turn while the link is READY (the Zenoh door's pump,
:class:`hilgate.gli.zenoh_door.SenderQueues`).  A node is one sender however many writers it opens on
the topic: its writers share its queue, rate and turn, so a process that opens 32 writers takes no
more of the link, nor more of the door's places, than one that opens one (a queue per writer let one
such process take every place: the next node was refused as ``clients``).  What a node sends beyond
its share is dropped and counted (``rate``, ``client_queue``); a sample that does not decode is
``bad_frame``; what Cyclone itself could not keep (the reader's history full, a best-effort sample
lost on the way) is counted too (``dds_rejected``, ``dds_lost``).  At most :data:`MAX_WRITERS` nodes
per link (then one over its share gives its place up to a newcomer).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

from cyclonedds.core import Listener

from ..core.backend import AppFrame
from ..core.endpoint import ABSENT, TAKEN, LinkPort
from ..core.packets import PacketError
from ..gli.zenoh_door import MAX_CLIENTS, Sender, SenderQueues
from .idl import message_class
from .participant import DDSException, Participant, guarded
from .poses import take_each

log = logging.getLogger(__name__)

__all__ = ["Ros2Door", "Ros2Endpoint", "FRAME", "MAX_WRITERS", "DOOR_BYTES"]

FRAME = "hilgate_msgs/msg/Frame"
BOOL = "std_msgs/msg/Bool"
MAX_WRITERS = MAX_CLIENTS  # nodes a link's door keeps queues for
MAX_PAYLOAD = 65536
DOOR_BYTES = 16 << 20  # bytes of frames all links' ROS 2 doors hold in all
READER_SAMPLES = 256   # samples Cyclone keeps for the reader before the listener takes them
NODES_KEPT = 4096       # writers whose participant is remembered


class Writer(Sender):
    """What the door holds for one node (a DDS participant) writing a link's ``send`` topic: its queue
    holds ``(data, dst)``."""

    __slots__ = ()

    @staticmethod
    def size(item: tuple[bytes, int]) -> int:
        return len(item[0])


class Ros2Endpoint(SenderQueues):
    kind = "ros2"
    source = "ros2"
    busy = False
    assumes_busy = False  # (hilgate.core.endpoint.Endpoint.assumes_busy: told BUSY by the link after a frame)
    phy = None  # (no PHY reports: hilgate.core.endpoint.Endpoint.phy)

    senders: dict[int, Writer]  # (by the participant's instance handle)

    def __init__(self, door: "Ros2Door", port: LinkPort):
        super().__init__(door, port)
        self.nodes: dict[int, int] = {}  # a writer's instance handle → its participant's (Cyclone's thread only)
        self.matched = 0  # subscriptions of recv (kept up to date by Cyclone: asking per frame costs more)
        self.Frame = message_class(FRAME)
        self.Bool = message_class(BOOL)
        participant, base = door.participant, door.base(port.id)
        self.topics = (base + "/send", base + "/recv", base + "/ready")
        reliability = door.reliability
        self.recv = participant.writer(self.topics[1], FRAME, reliability, depth=64,
                                       listener=Listener(on_publication_matched=self._matched))
        self.state_writer = participant.writer(self.topics[2], BOOL, "reliable", depth=1, durability="transient_local")
        self.reader = participant.reader(self.topics[0], FRAME, Listener(
            on_data_available=guarded(f"ros2 link {port.id}")(self._on_send),
            on_sample_rejected=guarded(f"ros2 link {port.id}")(self._on_rejected),
            on_sample_lost=guarded(f"ros2 link {port.id}")(self._on_lost)), reliability, keep_all=READER_SAMPLES)
        port.attach(self)

    def _matched(self, writer: Any, status: Any) -> None:  # (on Cyclone's thread; an int is set in one step)
        self.matched = status.current_count

    # -- link → nodes (on the loop) ---------------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        if not self.matched:
            return ABSENT  # no node subscribes: nothing to encode or send
        now = time.time()
        message = self.Frame()
        message.stamp.sec, message.stamp.nanosec = int(now), int((now % 1.0) * 1e9)
        message.src, message.dst, message.model_time = frame.src & 0xFF, frame.dst & 0xFF, t
        message.data = bytes(frame.payload)
        try:
            self.recv.write(message)
        except DDSException:  # its history is full of frames not yet acknowledged: never wait for them
            return "ros2_writer"
        return TAKEN

    def state(self, ready: bool) -> None:
        if ready != self.ready:
            self.ready = ready
            try:
                self.state_writer.write(self.Bool(data=ready))
            except DDSException as exc:
                log.debug("ros2 link %s: READY not published: %s", self.port.id, exc)
        if ready:
            self._pump()

    # -- nodes → link (on Cyclone's threads: counted and queued, never waiting) ----------------------

    def _on_send(self, reader: Any) -> None:
        for sample in take_each(reader, self._refuse_decode):
            if not hasattr(sample, "data"):  # (by name: a DDS sample, or the invalid one of a writer gone)
                continue  # a writer went away
            node = self._node_of(reader, sample.sample_info.publication_handle)
            data = bytes(sample.data)
            with self.lock:
                writer = self._place(node, lambda: Writer(node, f"{node:x}"))
                if writer is not None and self._admit(writer, len(data), MAX_PAYLOAD, DOOR_BYTES):
                    self._queue(writer, (data, sample.dst))
        self._wake()

    def _node_of(self, reader: Any, handle: int) -> int:
        """The participant (a node's process) of the writer ``handle``, as Cyclone's discovery knows it;
        the writer itself if discovery no longer knows it (it went away meanwhile)."""
        node = self.nodes.get(handle)
        if node is None:
            try:
                endpoint = reader.get_matched_publication_data(handle)
            except DDSException:
                endpoint = None
            node = endpoint.participant_instance_handle if endpoint is not None else handle
            if len(self.nodes) >= NODES_KEPT:
                self.nodes.clear()  # (writers made up by the thousand: the memory starts again)
            self.nodes[handle] = node
        return node

    def _refuse_decode(self, cause: str) -> None:
        with self.lock:
            self.refused["bad_frame"] = self.refused.get("bad_frame", 0) + 1

    def _on_rejected(self, reader: Any, status: Any) -> None:
        self._count("dds_rejected", status.total_count_change)

    def _on_lost(self, reader: Any, status: Any) -> None:
        self._count("dds_lost", status.total_count_change)

    def _count(self, cause: str, n: int) -> None:
        if n > 0:
            with self.lock:
                self.refused[cause] = self.refused.get(cause, 0) + n
            self._wake()

    def _wake(self) -> None:
        with self.lock:
            wake, self.posted = not self.posted, True
        if wake:
            self.door.post(self._pump)

    def _forward(self, item: tuple[bytes, int], sender: Sender) -> None:
        data, dst = item
        try:
            self.port.send_payload(data, dst)
        except PacketError as exc:
            self.port.lost("bad_frame", len(data), src="ros2")
            log.info("ros2 link %s: a frame refused: %s", self.port.id, exc)

    def close(self) -> None:
        self.port.detach(self)
        participant = self.door.participant
        for entity in (self.reader, self.recv, self.state_writer):
            participant.delete(entity)
        self._drop_queued()


class Ros2Door:
    """Opens the ROS 2 topics of the links whose ``gli:`` names ``ros2``, on ``node``'s participant
    (made when the first such link opens)."""

    def __init__(self, node: Any, post: Any, token: Any = None):
        self.node = node
        self.post = post
        self.token = token or (lambda name: name)
        self.queued = 0
        self.lock = threading.Lock()

    @property
    def participant(self) -> Participant:
        return self.node.participant

    @property
    def reliability(self) -> str:
        return self.node.spec.links_reliability

    def base(self, link_id: str) -> str:
        return f"{self.node.spec.namespace.rstrip('/')}/{self.token(link_id)}"

    def open(self, port: LinkPort) -> Ros2Endpoint | None:
        if "ros2" not in port.gli:
            return None
        return Ros2Endpoint(self, port)

    def update(self, handle: Ros2Endpoint | None, port: LinkPort) -> Ros2Endpoint | None:
        if handle is None:
            return self.open(port)
        if "ros2" not in port.gli:
            handle.close()
            return None
        return handle

    def close(self, handle: Ros2Endpoint | None) -> None:
        if handle is not None:
            handle.close()
