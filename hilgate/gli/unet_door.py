"""The UnetStack door: a link's applications connect as to a UnetStack node (``gli: [unet]``).

Many labs write their networking code against UnetStack's ``UnetSocket`` (``unetpy``, ``fjagepy`` beneath
it).  A link with ``gli: [..., unet]`` and ``unet: {tcp: 1100}`` serves a UnetStack node on that loopback
port (:mod:`hilgate.core.unet_server`, :mod:`hilgate.core.unet_node`), so such an application runs
unmodified on any link, simulated or a real modem of another family: ``UnetSocket("localhost",
1100)`` finds the node's agents, reads its address, and its datagrams are GLI frames.

A datagram's bytes are the application's payload, carried in the link's packet class as a socket
client's SEND is (a vl2b link's dccomms applications read it as theirs, and the other way round); its
``to`` is the frame's destination (UnetStack's broadcast, 0, is hilgate's 255).  A received frame is
published as the physical agent's ``RxFrameNtf`` with its source, destination, payload and the model's
arrival time, and the protocol number the door's ``protocol:`` gives (a frame of another family carries
none on air).  The datagram's fate: ``TxFrameNtf`` when the model's transmission ends (``txTime`` its
start), ``DatagramFailureNtf`` when the modem drops it, a ``RefuseRsp`` for one the link cannot carry
(too large for the packet class or the modem: the same words a socket client is told).
"""

from __future__ import annotations

import itertools
import logging
from typing import Any

from ..core.backend import AppFrame
from ..core.endpoint import LinkPort
from ..core.unet_node import Datagram
from ..core.unet_server import NodeServer

log = logging.getLogger(__name__)


class UnetEndpoint(NodeServer):
    """A link's UnetStack door: a node whose datagrams are the link's GLI frames."""

    kind = "unet"

    def __init__(self, port: LinkPort, scheduler: Any, options: dict[str, Any]):
        super().__init__(port, scheduler, int(options["tcp"]), str(options.get("host", "127.0.0.1")))
        self.options = options
        self.protocol = int(options.get("protocol", 0))
        self.seq = itertools.count(1)

    def mtu(self) -> int:
        """The largest payload the link's packet class carries, within what its modem accepts."""
        most = self.port.packet.max_payload
        limits = self.port.limits
        if limits is not None and limits.send_as is not None:
            size = limits.most(limits.send_as)
            if size is not None:
                overhead = len(self.port.packet.encode(b"", src=0, dst=0))
                most = min(most, max(0, size - overhead))
        return most

    def _frame(self, datagram: Datagram) -> AppFrame:
        port = self.port
        real = port.packet.encode(datagram.data, src=port.address, dst=datagram.to)
        return AppFrame(real, datagram.data, port.packet, next(self.seq) & 0xFFFFFFFF, port.address, datagram.to,
                        self.scheduler.now())

    def deliver(self, frame: AppFrame, t: float) -> str:
        return self.publish("phy", frame, t, frame.payload, self.protocol)


class UnetDoor:
    """Opens the UnetStack door of each link whose ``gli:`` names ``unet`` (a :class:`~hilgate.core.endpoint.Door`)."""

    def __init__(self, scheduler: Any):
        self.scheduler = scheduler

    def open(self, port: LinkPort) -> UnetEndpoint | None:
        if "unet" not in port.gli or not port.unet:
            return None
        endpoint = UnetEndpoint(port, self.scheduler, port.unet)
        port.attach(endpoint)
        return endpoint

    def update(self, handle: UnetEndpoint | None, port: LinkPort) -> UnetEndpoint | None:
        if handle is not None and "unet" in port.gli and handle.options == port.unet:
            return handle
        self.close(handle)
        return self.open(port)

    def close(self, handle: UnetEndpoint | None) -> None:
        if handle is not None:
            handle.port.detach(handle)
            handle.close()
