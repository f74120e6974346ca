"""The loop around a UnetStack node (:mod:`hilgate.core.unet_node`): its TCP port, its link, the model's times.

Two things in hilgate are a UnetStack node in front of a link, and both are this class with one
difference each: the UnetStack door (:mod:`hilgate.gli.unet_door`), an application's way onto any link,
whose datagrams are the application's payloads in the link's packet class; and the emulated UnetStack
modem (:mod:`hilgate.drivers.unet_emulator`), a simulated link that looks like a real modem, whose
datagrams are the modem's own bytes on air.  What they share is here:

- a loopback TCP listener (``host`` elsewhere only when the scene says so), at most :data:`MAX_CLIENTS`
  peers at once (a newcomer beyond is told why and closed, counted, as the GLI refuses one), each with
  at most :data:`OUTPUT_CAP` bytes of notifications it has not read (then it is closed: it stopped
  reading), and the node's own refusals (bad JSON, floods…, counted by cause in the link's status,
  ``unet_<cause>``, and traced);
- each datagram's fate from the link: its transmission as the simulated PHY reports it (``TxFrameNtf``
  with the model's start time), its acknowledgement (a reliable datagram's, from the model's ACK on
  the channel: :mod:`hilgate.models.acoustic_ack`), its drop before the air (``DatagramFailureNtf``);
  on a real modem's link, which reports no PHY, a datagram counts as sent when the link is READY again;
- each received frame's start on the channel (the PHY's ``rx_start``), UnetStack's ``rxTime``;
- what the node says leaves when the model says it (``TCP_NODELAY``: a line is one write, and a
  notification must not wait behind the peer's delayed acknowledgement of the answer before it).
"""

from __future__ import annotations

import logging
import socket
from abc import ABC, abstractmethod
from typing import Any

from .backend import AppFrame, PhyEvent
from .endpoint import ABSENT, TAKEN, LinkPort
from .packets import PacketError
from .streams import Connection, Listener, refuse
from . import fjage
from .unet_node import Datagram, UnetNode

log = logging.getLogger(__name__)

MAX_CLIENTS = 32       # peers of one node at once (the GLI's --max-link-clients default)
OUTPUT_CAP = 256 * 1024  # notifications kept for a peer that does not read (beyond: it is closed)
ARRIVALS_KEPT = 1024   # arrival starts remembered for frames not yet delivered (a bound, not a figure)
ACK_RETRIES = 2        # a reliable datagram's retransmissions (UnetStack's link agent retries a few times)
ANSWER_DELAY_S = 0.02  # what a peer is told after a question waits this long (wall clock; see hold())


class NodeServer(ABC):
    """A UnetStack node served on a TCP port in front of ``port`` (the module's docstring); an endpoint of
    the link.  A subclass says what a datagram is on the link (:meth:`_frame`) and what a received frame
    is to the node (:meth:`deliver`)."""

    busy = False
    assumes_busy = False

    def __init__(self, port: LinkPort, scheduler: Any, tcp: int, host: str = "127.0.0.1"):
        self.port = port
        self.scheduler = scheduler
        self.node = UnetNode(self)
        self.connections: set[Connection] = set()
        self.held: dict[Connection, list[bytes]] = {}  # what waits for a peer's answer delay (hold())
        self.refused_clients = 0
        self.awaiting: dict[int, tuple[AppFrame, Datagram]] = {}  # id(frame) → its datagram, until on air
        self.arrivals: dict[int, float] = {}  # id(frame) → when its arrival began
        self.closed = False
        sock = socket.create_server((host, tcp))
        sock.setblocking(False)
        self.listener = Listener(sock, scheduler, self._accept)
        self.where = f"{host}:{tcp}"
        log.info("%s: UnetStack node on tcp://%s", port.id, self.where)

    # -- peers ----------------------------------------------------------------------------------------

    def _accept(self, sock: socket.socket) -> None:
        if len(self.connections) >= MAX_CLIENTS:
            for connection in [c for c in self.connections if c.hung_up()]:
                connection.close()  # gone, though the loop has not read it yet: no place held
        if len(self.connections) >= MAX_CLIENTS:
            self.refused_clients += 1
            self.refused("clients")
            if self.refused_clients & (self.refused_clients - 1) == 0:
                log.warning("%s: UnetStack peer refused: %d connected already (%d refused so far)",
                            self.port.id, len(self.connections), self.refused_clients)
            refuse(sock, fjage.encode({"error": f"too many clients ({MAX_CLIENTS})"}))
            return
        # (with Nagle's algorithm a TxFrameNtf written just after the AGREE waited for the peer's delayed ACK,
        # up to 40 ms: the driver heard of its transmission after the far node had the frame)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        holder: list[Connection] = []
        connection = Connection(sock, self.scheduler, lambda data: self.node.receive(holder[0], data),
                                lambda: self._left(holder[0]), max_buffer=OUTPUT_CAP)
        holder.append(connection)
        self.connections.add(connection)
        self.node.connect(connection)

    def _left(self, connection: Connection) -> None:
        self.connections.discard(connection)
        self.held.pop(connection, None)
        self.node.leave(connection)

    def hold(self, client: Connection) -> None:
        """What the node says to ``client`` after its question waits :data:`ANSWER_DELAY_S` of the wall
        clock, in order.  fjagepy (2.1 to 3.0, so unetpy too) registers the wait for an answer only after
        it has sent the question, and drops an answer that comes before (a directory action's fails with
        a KeyError, a request's reply waits out its timeout): on loopback a node that answers at once
        loses that race whenever the kernel runs it before the asking thread is back from its send.  A
        real node's answer takes a network's and a JVM's time; this is that time."""
        if client not in self.held:
            self.held[client] = []
            self.scheduler.after_wall(ANSWER_DELAY_S, self._release, client)

    def _release(self, client: Connection) -> None:
        for data in self.held.pop(client, ()):
            if not self._send(client, data):
                break

    def write(self, client: Connection, data: bytes) -> bool:
        held = self.held.get(client)
        if held is not None:
            if sum(map(len, held)) + len(data) > OUTPUT_CAP:  # a flood of questions: not kept without end
                self.node.count("client_slow")
                client.close()
                return False
            held.append(data)
            return not client.closed
        return self._send(client, data)

    def _send(self, client: Connection, data: bytes) -> bool:
        if client.write(data):
            return True
        if not client.closed and not client.write_failed:
            self.node.count("client_slow")
            log.info("%s: UnetStack peer stopped reading: closed", self.port.id)
            client.close()
        return False

    def close_client(self, client: Connection) -> None:
        client.close()

    def refused(self, cause: str) -> None:
        """Counted in the link's status (``drop_causes``, ``unet_<cause>``) and traced (``ev: refused``)."""
        self.port.lost(f"unet_{cause}", 0, src="unet", ev="refused")

    # -- the node's host (hilgate.core.unet_node.NodeHost) -------------------------------------------------

    @property
    def node_name(self) -> str:
        return self.port.id

    @property
    def address(self) -> int:
        return self.port.address

    def now(self) -> float:
        return self.scheduler.now()

    def set_address(self, address: int) -> bool:
        return False

    def resolve(self, name: str) -> int | None:
        return self.port.address_of(name)

    @abstractmethod
    def mtu(self) -> int:
        """The largest datagram the node sends (bytes)."""

    def phy_params(self) -> dict[str, Any]:
        mtu = self.mtu()
        bitrate = self.port.bitrate_bps
        return {"MTU": mtu, "dataRate": round(bitrate, 3), "frameDuration": round(mtu * 8.0 / bitrate, 6),
                "busy": not self.port.ready}

    @property
    def simulated(self) -> bool:
        """The link is a simulated modem, whose PHY reports each transmission's time."""
        return self.port.airtime(1) is not None

    def transmit(self, datagram: Datagram) -> str | None:
        if datagram.reliable and not self.simulated:
            return "reliable datagrams need the simulated link's acknowledgements (this link is a real modem)"
        frame = self._frame(datagram)
        frame.on_dropped = self._dropped
        if datagram.reliable:
            frame.ack_retries = ACK_RETRIES
            frame.on_acknowledged = self._acknowledged
        self.awaiting[id(frame)] = (frame, datagram)
        try:
            self.port.send(frame)
        except PacketError as exc:
            self.awaiting.pop(id(frame), None)
            self.port.lost(exc.reason, len(frame.real), src="unet")
            return str(exc)
        return None

    @abstractmethod
    def _frame(self, datagram: Datagram) -> AppFrame:
        """The frame ``datagram`` is on the link."""

    def _dropped(self, frame: AppFrame, cause: str) -> None:
        entry = self.awaiting.pop(id(frame), None)
        if entry is not None:
            self.node.failed(entry[1], f"dropped by the modem ({cause})")

    def _acknowledged(self, frame: AppFrame, delivered: bool, tau: float | None) -> None:
        entry = self.awaiting.pop(id(frame), None)
        if entry is None:
            return
        if delivered:
            self.node.delivered(entry[1])
        else:
            self.node.failed(entry[1], "no acknowledgement")

    # -- the link's reports ----------------------------------------------------------------------------

    def phy(self, event: PhyEvent) -> None:
        frame = event.frame
        if frame is None:
            return
        if event.kind == "tx":
            entry = self.awaiting.get(id(frame))
            if entry is not None and entry[0] is frame and not entry[1].reliable:
                del self.awaiting[id(frame)]
                start = event.start if event.start is not None else event.end
                self.scheduler.at(event.end, self.node.transmitted, entry[1], start)
        elif event.kind == "rx_start" and event.start is not None:
            if len(self.arrivals) >= ARRIVALS_KEPT:
                self.arrivals.pop(next(iter(self.arrivals)))
            self.arrivals[id(frame)] = event.start
        elif event.kind == "rx_end" and event.cause is not None:
            self.arrivals.pop(id(frame), None)

    def arrival_start(self, frame: AppFrame, t: float) -> float:
        """When ``frame``'s arrival began on the channel (UnetStack's ``rxTime``): the PHY's report, else
        its end less its air time."""
        start = self.arrivals.pop(id(frame), None)
        if start is not None:
            return start
        airtime = frame.airtime_s if frame.airtime_s is not None else self.port.airtime(len(frame.real))
        return t - (airtime or 0.0)

    def publish(self, agent: str, frame: AppFrame, t: float, data: bytes, protocol: int) -> str:
        heard = self.port.reception_from(frame.src, t)
        given = self.node.received(agent, frame.src, frame.dst, protocol, data, self.arrival_start(frame, t),
                                   heard.rssi_db if heard is not None else None)
        return TAKEN if given else ABSENT

    def state(self, ready: bool) -> None:
        """READY/BUSY: a reload may have changed the link's address (told to the peers), and on a real
        modem's link the datagrams handed to it count as sent once it is READY again."""
        self.node.address_changed()
        if ready and not self.simulated and self.awaiting:
            now = self.scheduler.now()
            for key, (frame, datagram) in list(self.awaiting.items()):
                if not datagram.reliable:
                    del self.awaiting[key]
                    self.node.transmitted(datagram, now)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self.listener.close()
        for connection in list(self.connections):
            connection.close()
