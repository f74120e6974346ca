"""The daemon's side of ROS 2 (:mod:`hilgate.ros2`): the door it gives the router for links on ROS 2,
the participant live pose sources read on, and the publisher of poses, ``/tf`` and ``/diagnostics``.

Nothing of Cyclone DDS is imported until a scene uses ROS 2 (a ``ros2:`` section, a ``ros2`` pose, a
link whose ``gli:`` names ``ros2``): a daemon of a scene without ROS 2 never loads it, and without the
extra the scene loader has refused such a scene already.  The door is in the router's list from the
start, so a reload can put a link on ROS 2; it opens the real door on first need.
"""

from __future__ import annotations

import logging
from typing import Any

from ..core.endpoint import LinkPort
from ..scene import Scene, SceneError
from ..scene.ros2 import Ros2Spec, ros_token

log = logging.getLogger(__name__)

__all__ = ["Ros2Bridge"]


class Ros2Bridge:
    """One per daemon: ``prepare`` a scene (before the router applies it), ``apply`` it after."""

    def __init__(self, scheduler: Any, router: Any, scene_path: str):
        self.scheduler = scheduler
        self.router = router
        self.scene_path = scene_path
        self.node: Any = None      # hilgate.ros2.node.Ros2Node, once a scene used ROS 2
        self.door: Any = None      # hilgate.ros2.door.Ros2Door, once a link opened on ROS 2
        self.publisher: Any = None
        self._published: Any = None  # the spec the publisher was made from

    # -- the scene ------------------------------------------------------------------------------

    def prepare(self, scene: Scene) -> None:
        """Refuse (SceneError) what cannot be applied; take the section's settings."""
        if not scene.uses_ros2:
            return
        spec = scene.ros2 or Ros2Spec()
        from ..ros2.node import Ros2Error, Ros2Node, domain_from

        try:
            domain_from(spec)
            if self.node is None:
                self.node = Ros2Node(spec)
            else:
                self.node.configure(spec)
        except Ros2Error as exc:
            raise SceneError(self.scene_path, 0, "ros2", str(exc)) from None

    def apply(self, scene: Scene) -> None:
        """After the router applied ``scene``: publish what its ``ros2.publish`` lists, nothing else."""
        spec = scene.ros2
        wanted = spec if spec is not None and (spec.poses or spec.tf or spec.diagnostics) else None
        if wanted == self._published:
            return
        if self.publisher is not None:
            self.publisher.close()
            self.publisher = None
        self._published = wanted
        if wanted is not None:
            from ..ros2.publish import Publisher

            self.publisher = Publisher(self.node.participant, self.scheduler, wanted, self._vehicles,
                                       self._links, ros_token)

    def _vehicles(self) -> list:
        """Each vehicle's state as a function the publisher calls in its turn (model time then)."""
        now = self.scheduler.now

        def state(name: str, pose: Any) -> Any:
            def get() -> tuple:
                t = now()
                return name, pose.position(t), pose.attitude, pose.age(t), pose.stale(t)
            return get

        return [state(name, pose) for name, pose in self.router.world.poses.items()]

    def _links(self) -> list:
        return [link.status for link in self.router.links.values()]

    # -- for live pose sources --------------------------------------------------------------------

    def participant(self) -> Any:
        return self.node.participant

    @property
    def frame(self) -> str:
        return self.node.spec.frame

    # -- the door (core.endpoint.Door) ---------------------------------------------------------------

    def open(self, port: LinkPort) -> Any:
        if "ros2" not in port.gli:
            return None
        return self._door().open(port)

    def update(self, handle: Any, port: LinkPort) -> Any:
        if handle is None and "ros2" not in port.gli:
            return None
        return self._door().update(handle, port)

    def close(self, handle: Any) -> None:
        if handle is not None:
            handle.close()

    def _door(self) -> Any:
        if self.door is None:
            from ..ros2.door import Ros2Door

            self.door = Ros2Door(self.node, self.scheduler.post, ros_token)
        return self.door

    # -- operations -----------------------------------------------------------------------------------

    def status(self) -> dict | None:
        if self.node is None or not self.node.started:
            return None
        status: dict[str, Any] = {"domain_id": self.node.domain_id, "namespace": self.node.spec.namespace,
                                  "interfaces": list(self.node.spec.interfaces) or ["loopback"]}
        if self.publisher is not None:
            status.update(self.publisher.status())
        return status

    def shutdown(self) -> None:
        """Last, after the router closed the links' endpoints and the live sources their readers."""
        if self.publisher is not None:
            self.publisher.close()
            self.publisher = None
        if self.node is not None:
            self.node.close()
