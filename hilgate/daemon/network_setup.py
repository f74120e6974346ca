"""A daemon's place in a scene spread over hosts: its host name, its credentials, and joining the network.

Apart from the daemon because only a daemon of several hosts needs it (the ``zenoh`` row of the door
table opens it), and its refusals are the scene's errors: a wrong ``--host`` or missing credentials
refuse the start before anything opens."""

from __future__ import annotations

import logging
import socket
from typing import Any

from ..gli.zenoh_auth import CredentialError, Identity, load_identity
from ..scene import Scene, SceneError
from ..scene.hosts import HOST_NAME, ZenohSpec

__all__ = ["host_of", "identity_of", "join"]

log = logging.getLogger(__name__)


def host_of(options: Any, scene: Scene) -> str | None:
    """This daemon's host name in a scene spread over hosts (None: the scene is for one daemon)."""
    if not (scene.multi_host or options.host or options.zenoh_connect or options.zenoh_listen):
        return None
    host = options.host or socket.gethostname().split(".")[0]
    if not HOST_NAME.fullmatch(host):
        raise SceneError("--host", 0, "", f"{host!r} is not a host name (letters, digits, '_', '.', '-')")
    if options.speed != 1.0:
        raise SceneError("--speed", 0, "", "a daemon of several hosts runs at real time (--speed 1): model "
                                           "times cross hosts through the UNIX clock")
    if scene.hosts and host not in scene.hosts:
        raise SceneError(options.scene_path, 0, "", f"this daemon is host {host!r} but the scene's hosts are "
                                                    f"{', '.join(scene.hosts)}: give --host")
    return host


def identity_of(options: Any, spec: ZenohSpec, host: str, scene: Scene | None) -> Identity | None:
    """This host's credentials, or None when the network is insecure, asked for in so many words."""
    path = options.zenoh_credentials or spec.credentials
    if path is None:
        if not (spec.insecure or options.zenoh_insecure):
            raise SceneError(options.scene_path, 0, "", "a scene of several hosts says where the lab's credentials "
                             "are (zenoh: {credentials: DIR}, from: hilgate network init DIR --hosts ...) or "
                             "that the network is open to anyone who reaches it (zenoh: {insecure: true})")
        log.warning("INSECURE network: Zenoh without credentials (zenoh.insecure): anyone who reaches %s "
                    "can send frames, forge hosts and read everything",
                    ", ".join(options.zenoh_listen or spec.listen))
        return None
    try:
        identity = load_identity(path, host, "host")
    except CredentialError as exc:
        raise SceneError(options.scene_path, 0, "", str(exc)) from None
    missing = [name for name in (scene.hosts if scene else ()) if name not in identity.hosts]
    if missing:
        log.warning("the credentials in %s do not list host(s) %s of the scene: their daemons will not be "
                    "heard (run hilgate network init again with every host)", identity.directory, ", ".join(missing))
    return identity


def join(setting: Any) -> tuple[Any, Any]:
    """The daemon's :class:`~hilgate.daemon.network.Network` and its door (a ``doors.DoorSetting`` with a
    host): the scene's links claimed before anything opens, so a refused daemon touches nothing."""
    from .network import Network

    options, scene = setting.options, setting.scene
    spec = scene.zenoh or ZenohSpec()
    network = Network(setting.scheduler, setting.router, setting.recorder, setting.host, spec,
                      list(options.zenoh_connect), list(options.zenoh_listen), options.clock_offset_s,
                      identity_of(options, spec, setting.host, scene))
    door = network.open()
    network.claim(scene)
    setting.router.network = network
    return network, door
