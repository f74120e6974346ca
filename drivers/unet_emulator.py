"""A UnetStack modem (Subnero's) in front of a simulated link, on a loopback TCP port.

``emulate: {protocol: unet, tcp: 1100}`` serves the modem's fjåge API there
(:mod:`hilgate.core.unet_server`, :mod:`hilgate.core.unet_node`), with the link's simulated modem behind
it, so ``unetpy``, ``fjagepy`` and hilgate's own ``unet`` driver meet the other families on one channel:

- a datagram's bytes are what the modem puts on air (a frame of its own, as an EvoLogics IM's bytes
  are); the channel carries its agent and protocol number with it, so another emulated UnetStack modem
  publishes it as its ``phy`` (``RxFrameNtf``) or ``uwlink`` (``DatagramNtf``) would, with the sender's
  protocol; the applications of a simulated link that hears it (dccomms, sockets, another door) get those
  bytes parsed as one frame of their packet class, as a bridge on the receiving side would (a ``raw``
  link takes them as they are);
- a frame of another family reaches the node's ``phy`` as its bytes on air, with the protocol number
  ``unet_protocol`` gives (0, ``DATA``, by default: none is on air);
- the node's ``address`` is the link's, and setting it (``node.address = 5``) moves the link in the
  simulation, as ``AT!AL`` does an emulated EvoLogics modem (a reload gives it its scene address again);
- ``MTU`` is the link's ``limits:`` datagram size (``models/unet-m25m.yaml``), ``dataRate`` its bit rate;
  a datagram larger than the MTU is refused (``RefuseRsp``), as the modem refuses it;
- timing and fates are the model's: ``TxFrameNtf`` when the transmission ends (``txTime`` its start, µs of
  model time), ``rxTime`` the arrival's start, a reliable datagram (``uwlink``) acknowledged on the
  channel (``DatagramDeliveryNtf``) or failed after its retries (``DatagramFailureNtf``), one the modem's
  FIFO had no room for failed at once.

Not emulated: UnetStack's other agents (MAC, routing, transport, remote, ranging, baseband), its shell,
fragmentation above the MTU, the modem's own frame header on air (hilgate's frame is the datagram).
"""

from __future__ import annotations

import logging
from typing import Any

from hilgate.core.backend import AppFrame
from hilgate.core.endpoint import LinkPort
from hilgate.core.packets import Raw
from hilgate.core.unet_node import Datagram
from hilgate.core.unet_server import NodeServer

from .table import UNET_LIMITS, limits_for

log = logging.getLogger(__name__)


class UnetEmulator(NodeServer):
    """A UnetStack modem (the module's docstring); an endpoint of kind ``emulator``."""

    kind = "emulator"

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        self.options = spec
        self.protocol = int(spec.get("unet_protocol", 0))
        super().__init__(port, scheduler, int(spec["tcp"]))

    def mtu(self) -> int:
        limits = limits_for("unet", self.port.limits) or UNET_LIMITS
        return limits.most("datagram") or 0

    def set_address(self, address: int) -> bool:
        self.port.set_address(address)
        return self.port.address == address

    def _frame(self, datagram: Datagram) -> AppFrame:
        frame = AppFrame(datagram.data, datagram.data, Raw(), 0, self.port.address, datagram.to, self.scheduler.now())
        frame.meta = {"unet": datagram.agent, "protocol": datagram.protocol}
        return frame

    def deliver(self, frame: AppFrame, t: float) -> str:
        meta = frame.meta or {}
        if "unet" in meta:
            return self.publish(meta["unet"], frame, t, frame.payload, meta["protocol"])
        return self.publish("phy", frame, t, frame.real, self.protocol)
