"""A stand-in for a ROS 2 node: a second Cyclone DDS participant in the test process, on loopback, in a
DDS domain drawn at random for this test run (so concurrent runs on the machine never hear each other),
reading and writing the same topics and types a ROS 2 node would.

It reads the bytes as they came off the wire (``raw``) so that tests can hold them against rosbags'
CDR, and can write any bytes at all (``write_raw``), as a broken or hostile node would.
"""

from __future__ import annotations

import random
import threading
import uuid

import pytest

cyclonedds = pytest.importorskip("cyclonedds")  # the test extra installs it

from cyclonedds._clayer import ddspy_take, ddspy_write  # noqa: E402
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication  # noqa: E402
from cyclonedds.core import Listener, Policy, Qos  # noqa: E402
from cyclonedds.internal import InvalidSample  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.core import SampleState, ViewState, InstanceState  # noqa: E402

from hilgate.ros2.idl import message_class  # noqa: E402
from hilgate.ros2.participant import Participant, qos  # noqa: E402
from daemon_kit import wait_until

DOMAIN = random.SystemRandom().randrange(0, 233)
ANY = SampleState.Any | ViewState.Any | InstanceState.Any
_node: Participant | None = None


def node() -> Participant:
    """The test process's one participant (Cyclone allows one configuration per domain and process)."""
    global _node
    if _node is None:
        _node = Participant(DOMAIN)
    return _node


def namespace() -> str:
    return f"/t{uuid.uuid4().hex[:10]}"


class Subscription:
    """Every sample on ``topic``: decoded (``samples``) and as the wire carried it (``raw``)."""

    def __init__(self, topic: str, type_name: str, reliability: str = "reliable", durability: str = "volatile"):
        self.type_name = type_name
        self.raw: list[bytes] = []
        self.samples: list = []
        self.lock = threading.Lock()
        policies = qos(type_name, reliability, depth=1000, durability=durability)
        self.reader = DataReader(node().participant, node()._topic(topic, type_name), qos=policies,
                                 listener=Listener(on_data_available=self._on_data))

    def _on_data(self, reader):
        taken = ddspy_take(reader._ref, ANY, 1000)
        if isinstance(taken, int):
            return
        cls = message_class(self.type_name)
        with self.lock:
            for data, info in taken:
                if info.valid_data:
                    self.raw.append(bytes(data))
                    self.samples.append(cls.deserialize(data))

    def wait(self, count: int = 1, timeout: float = 60.0) -> list:
        wait_until(lambda: len(self.samples) >= count, f"{count} samples of {self.type_name}", timeout)
        with self.lock:
            return list(self.samples)

    def close(self):
        node().delete(self.reader)


class Publication:
    def __init__(self, topic: str, type_name: str, reliability: str = "reliable"):
        self.type_name = type_name
        self.writer = DataWriter(node().participant, node()._topic(topic, type_name),
                                 qos=qos(type_name, reliability, depth=100))

    def matched(self) -> int:
        return self.writer.get_publication_matched_status().current_count

    def write(self, message) -> None:
        self.writer.write(message)

    def write_raw(self, data: bytes) -> None:
        """Any bytes at all as a sample (a CDR header first), as a broken node would send them."""
        assert ddspy_write(self.writer._ref, data) >= 0

    def close(self):
        node().delete(self.writer)


def publications(topic_prefix: str) -> dict[str, tuple[str, bytes]]:
    """Every writer the discovery shows under ``rt<topic_prefix>``: topic → (type name, USER_DATA)."""
    reader = BuiltinDataReader(node().participant, BuiltinTopicDcpsPublication)
    try:
        found = {}
        for sample in reader.read(N=1000):
            if isinstance(sample, InvalidSample) or not sample.topic_name.startswith("rt" + topic_prefix):
                continue
            found[sample.topic_name] = (sample.type_name, sample.qos[Policy.Userdata].data
                                        if Policy.Userdata in sample.qos else b"")
        return found
    finally:
        node().delete(reader)


def ros2_section(ns: str, extra: str = "") -> str:
    return f"ros2:\n  domain_id: {DOMAIN}\n  namespace: {ns}\n{extra}"


def ros2_scene(ns: str, vehicles: str, links: str, extra: str = "") -> str:
    """A scene on one acoustic channel whose ``ros2`` section is in this run's domain under ``ns``:
    ``vehicles`` and ``links`` are the lines of those sections, ``extra`` more lines of ``ros2``."""
    return f"channels: {{ac: {{speed_mps: 1500}}}}\nvehicles:\n{vehicles}links:\n{links}{ros2_section(ns, extra)}"


def node_and_app_scene(ns: str, node_link: str, app_link: str, distance_m: float, bitrate_bps: float,
                       app_gli: str = "") -> str:
    """Two vehicles ``distance_m`` apart: ``node_link`` on ROS 2 topics, ``app_link`` for a dccomms application."""
    return ros2_scene(ns, f"  a: {{pose: {{static: [0, 0, 0]}}}}\n  b: {{pose: {{static: [{distance_m}, 0, 0]}}}}\n",
                      f"  {node_link}: {{vehicle: a, address: 1, bitrate_bps: {bitrate_bps}, gli: [ros2]}}\n"
                      f"  {app_link}: {{vehicle: b, address: 2, bitrate_bps: {bitrate_bps}{app_gli}}}\n")


@pytest.fixture
def dds():
    """DDS entities for a test: ``dds(Subscription(...))`` returns the entity and closes it after the test
    (before the test's daemons are closed, when the test asks for ``daemon_of`` first)."""
    opened = []

    def keep(entity):
        opened.append(entity)
        return entity

    yield keep
    for entity in reversed(opened):
        entity.close()
