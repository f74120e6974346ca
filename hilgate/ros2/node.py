"""hilgate's presence on ROS 2: the domain it joins and its one participant, made on first use.

The domain is the scene's ``ros2.domain_id``, else the daemon's ``ROS_DOMAIN_ID`` (as every ROS 2 node
takes it), else 0.  What the participant is made with (domain, interfaces, peers) and what the links'
topics are named after (namespace, reliability) stay for the daemon's life: a reload that changes them
is refused with a line saying to restart, rather than moving every node's topics under its feet.
"""

from __future__ import annotations

import logging
import os
from typing import Any

from .participant import DDSException, Participant

log = logging.getLogger(__name__)

__all__ = ["Ros2Node", "Ros2Error", "domain_from"]

MAX_DOMAIN_ID = 232


class Ros2Error(ValueError):
    """A one-line reason hilgate cannot be on ROS 2 as asked."""


def domain_from(spec: Any, environ: dict | None = None) -> int:
    if spec.domain_id is not None:
        return spec.domain_id
    value = (os.environ if environ is None else environ).get("ROS_DOMAIN_ID", "").strip()
    if not value:
        return 0
    if not value.isdigit() or int(value) > MAX_DOMAIN_ID:
        raise Ros2Error(f"ROS_DOMAIN_ID={value[:20]!r} is not a domain id from 0 to {MAX_DOMAIN_ID}")
    return int(value)


def fixed_part(spec: Any) -> tuple:
    return (*spec.participant, spec.namespace, spec.links_reliability)


class Ros2Node:
    def __init__(self, spec: Any):
        self.spec = spec
        self._participant: Participant | None = None
        self.domain_id: int | None = None

    def configure(self, spec: Any) -> None:
        """Take a reloaded scene's section; Ros2Error if it changes what needs a restart."""
        if self._participant is not None and fixed_part(spec) != fixed_part(self.spec):
            raise Ros2Error("domain_id, interfaces, peers, namespace and links are fixed while the daemon "
                            "runs (ROS 2 nodes hold its topics): restart it to change them")
        self.spec = spec

    @property
    def participant(self) -> Participant:
        if self._participant is None:
            spec = self.spec
            self.domain_id = domain_from(spec)
            where = ", ".join(spec.interfaces) if spec.interfaces else "loopback"
            try:
                self._participant = Participant(self.domain_id, spec.interfaces, spec.peers)
            except DDSException as exc:  # Cyclone has said why on stderr (an interface that is not there…)
                raise Ros2Error(f"ros2: cannot join DDS domain {self.domain_id} on {where}: {exc}") from None
            log.info("ROS 2: joined DDS domain %d on %s (namespace %s)", self.domain_id,
                     where if spec.interfaces else "loopback only", spec.namespace)
        return self._participant

    @property
    def started(self) -> bool:
        return self._participant is not None

    def close(self) -> None:
        if self._participant is not None:
            self._participant.close()
            self._participant = None
