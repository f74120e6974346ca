"""hilgate's one DDS participant: where it talks (loopback unless the scene names interfaces), on which
domain, and the readers and writers the rest of :mod:`hilgate.ros2` asks for.

Every endpoint is made the way a ROS 2 node makes its own: the topic mangled (``/x`` → ``rt/x``), the
type named ``pkg::msg::dds_::Name_``, the QoS stated (reliable or best effort, a history depth, a
durability) and ``typehash=RIHS01_…;`` in its USER_DATA.  Writers never block: a reliable writer whose
history is full fails the write at once (``max_blocking_time`` 0) and the caller counts the loss.

Cyclone DDS calls listeners on its own threads.  What they run here must not raise (an exception in a
ctypes callback is a traceback on stderr): :func:`guarded` logs instead.
"""

from __future__ import annotations

import functools
import logging
import threading
from typing import Any, Callable
from xml.sax.saxutils import quoteattr

from cyclonedds.core import DDSException, Listener, Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from .idl import message_class
from .messages import dds_topic, user_data

log = logging.getLogger(__name__)

__all__ = ["Participant", "config_xml", "qos", "guarded", "DDSException", "MAX_SAMPLE_BYTES"]

MAX_SAMPLE_BYTES = 1 << 20
"""Samples larger than this are dropped by Cyclone DDS itself, before any Python sees them: a frame is at
most 64 KiB, a DiagnosticArray of a thousand links some 300 KiB."""
MAX_PARTICIPANT_INDEX = 120
"""Participants Cyclone looks for on each unicast peer (loopback): one port pair each."""


def config_xml(interfaces: tuple[str, ...] = (), peers: tuple[str, ...] = ()) -> str:
    """Cyclone DDS's configuration.  No interfaces: loopback only, discovery by unicast to the
    participants of this host (loopback carries no multicast); interfaces named: those only, with
    multicast discovery as ROS 2 nodes do by default, plus ``peers`` if given."""
    if not interfaces:
        general = ('<Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
                   '<AllowMulticast>false</AllowMulticast>')
        peers = ("127.0.0.1", *peers)
    else:
        named = "".join(f"<NetworkInterface {'address' if _is_address(i) else 'name'}={quoteattr(i)}/>"
                        for i in interfaces)
        general = f"<Interfaces>{named}</Interfaces>"
    discovery = ""
    if peers:
        discovery = ("<Discovery><ParticipantIndex>auto</ParticipantIndex>"
                     f"<MaxAutoParticipantIndex>{MAX_PARTICIPANT_INDEX}</MaxAutoParticipantIndex><Peers>"
                     + "".join(f"<Peer address={quoteattr(p)}/>" for p in peers) + "</Peers></Discovery>")
    return (f'<CycloneDDS><Domain id="any"><General>{general}</General>{discovery}'
            f"<Internal><MaxSampleSize>{MAX_SAMPLE_BYTES}B</MaxSampleSize></Internal></Domain></CycloneDDS>")


def _is_address(text: str) -> bool:
    return text.replace(".", "").isdigit() or ":" in text


def qos(type_name: str, reliability: str = "reliable", depth: int = 10, durability: str = "volatile",
        keep_all: int = 0) -> Qos:
    """A ROS 2 endpoint's QoS, with the type hash in USER_DATA.  ``keep_all`` > 0: keep every sample up
    to that many (a reader that takes everything at once: what it cannot hold is rejected, and counted)."""
    policies = [
        Policy.Reliability.Reliable(duration(seconds=0)) if reliability == "reliable" else Policy.Reliability.BestEffort,
        Policy.Durability.TransientLocal if durability == "transient_local" else Policy.Durability.Volatile,
        Policy.Userdata(user_data(type_name)),
    ]
    if keep_all:
        policies += [Policy.History.KeepAll, Policy.ResourceLimits(max_samples=keep_all, max_instances=-1,
                                                                    max_samples_per_instance=keep_all)]
    else:
        policies.append(Policy.History.KeepLast(depth))
    return Qos(*policies)


def guarded(what: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """A listener body that logs what it raises instead of printing a traceback from Cyclone's thread."""
    def wrap(fn: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(fn)
        def call(*args: Any) -> None:
            try:
                fn(*args)
            except Exception as exc:
                log.error("%s: %s: %s", what, type(exc).__name__, exc)
        return call
    return wrap


class Participant:
    """The daemon's DDS participant on ``domain_id``.  Topics are made once per name."""

    def __init__(self, domain_id: int, interfaces: tuple[str, ...] = (), peers: tuple[str, ...] = ()):
        self.domain_id = domain_id
        self.interfaces = interfaces
        self.domain = Domain(domain_id, config_xml(interfaces, peers))
        self.participant = DomainParticipant(domain_id)
        self.topics: dict[str, Any] = {}
        self.entities: list[Any] = []
        self.lock = threading.Lock()

    def _topic(self, topic: str, type_name: str) -> Any:
        name = dds_topic(topic)
        with self.lock:
            existing = self.topics.get(name)
            if existing is None:
                existing = self.topics[name] = (Topic(self.participant, name, message_class(type_name)), type_name)
        if existing[1] != type_name:
            raise ValueError(f"topic {topic} carries {existing[1]}, not {type_name}")
        return existing[0]

    def writer(self, topic: str, type_name: str, reliability: str = "reliable", depth: int = 10,
               durability: str = "volatile", listener: Listener | None = None) -> DataWriter:
        writer = DataWriter(self.participant, self._topic(topic, type_name),
                            qos=qos(type_name, reliability, depth, durability), listener=listener)
        self.entities.append(writer)
        return writer

    def reader(self, topic: str, type_name: str, listener: Listener, reliability: str = "reliable",
               keep_all: int = 256) -> DataReader:
        reader = DataReader(self.participant, self._topic(topic, type_name),
                            qos=qos(type_name, reliability, keep_all=keep_all), listener=listener)
        self.entities.append(reader)
        return reader

    def delete(self, entity: Any) -> None:
        """Delete a reader or writer now (its listener is not called again once this returns)."""
        if entity in self.entities:
            self.entities.remove(entity)
        try:
            entity.__del__()  # cyclonedds deletes an entity there (and forgets it)
        except Exception as exc:
            log.debug("deleting %r: %s", entity, exc)

    def close(self) -> None:
        for entity in list(self.entities):
            self.delete(entity)
        for topic, _ in self.topics.values():
            self.delete(topic)
        self.topics = {}
        self.delete(self.participant)
        self.delete(self.domain)
