"""A UnetStack node as its fjåge API shows it, without I/O: the agents a UnetSocket application talks to.

``unetpy``'s ``UnetSocket`` and ``fjagepy``'s ``Gateway`` do not talk to a modem: they talk to a fjåge
container whose agents offer UnetStack's services.  What they ask of it, read from their public sources
and UnetStack's documentation, is small, and this node answers exactly that:

- the **directory**: ``agents``, ``containsAgent``, ``services``, ``agentForService(s)`` over four
  agents: ``node`` (``NODE_INFO``), ``phy`` (``PHYSICAL`` and ``DATAGRAM``), ``uwlink`` (``LINK`` and
  ``DATAGRAM``) and ``arp`` (``ADDRESS_RESOLUTION``: ``UnetSocket.host(name)``);
- **parameters** (``ParameterReq`` → ``ParameterRsp``, named short or in full): the node's ``address``
  (and its change, ``ParamChangeNtf`` on the parameter-change topic and the node's own), ``nodeName``,
  ``time``; the physical agent's ``MTU``, ``time``, ``busy`` and, per frame type (``phy[1]``, ``phy[2]``),
  ``MTU``, ``dataRate``, ``frameLength``, ``frameDuration``, from the link's preset;
- **datagrams**: a ``DatagramReq`` (or ``TxFrameReq``) to ``phy`` or ``uwlink`` is AGREEd or refused
  (``RefuseRsp`` with the reason: too long for the MTU, reliability asked of the physical agent, a bad
  field); its fate comes back from the host: ``TxFrameNtf`` (phy) or ``DatagramTransmissionNtf``
  (uwlink) with the model's transmit time, ``DatagramDeliveryNtf``/``DatagramFailureNtf`` for a reliable
  one (the model's acknowledgement), ``DatagramFailureNtf`` for one the modem dropped; received frames
  are published as ``RxFrameNtf`` (phy, with the model's ``rxTime``) or ``DatagramNtf`` (uwlink) on the
  agent's topic, with ``from``, ``to``, ``protocol`` and the bytes;
- **subscriptions**: each peer gets what it said it wants (``wantsMessagesFor``: its own id, its
  topics), once per message; messages for another peer's id or topics are passed on, as a container does.

Times are the model's, in microseconds since the run began (UnetStack's ``time`` is the node's own
microsecond clock).  UnetStack's broadcast address is 0; hilgate's is 255: the node speaks UnetStack's,
the host hilgate's.  The host (the door or the emulated modem) owns the sockets, the link and the clock:
:class:`NodeHost`.  What a peer says that the node cannot act on is refused once, counted by cause in
:attr:`UnetNode.refused`, and never raises: bad JSON and over-long lines close that peer, as the other
doors close a client that breaks the framing; an unknown action or a message no agent understands is
answered (so a gateway does not wait for a timeout) and the peer stays.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

from . import fjage
from .fjage import Alive, Bad, Deliver, FjageCodec, Request, Response, Wants

log = logging.getLogger(__name__)

UNET_BROADCAST = 0
HILGATE_BROADCAST = 255
SERVICE = "org.arl.unet.Services."
PARAMCHANGE = "#org.arl.unet.Topics.PARAMCHANGE"
AGENTS: dict[str, tuple[str, ...]] = {
    "node": ("NODE_INFO",),
    "phy": ("PHYSICAL", "DATAGRAM"),
    "uwlink": ("LINK", "DATAGRAM"),
    "arp": ("ADDRESS_RESOLUTION",),
}
"""The node's agents and the services each offers (UnetStack's names; ``uwlink`` is its default link agent)."""
DATAGRAM_AGENTS = ("phy", "uwlink")
DATA_FRAME = 2  # UnetStack's frame types: 1 CONTROL, 2 DATA (phy[1], phy[2])
MAX_PROTOCOL = 63
RATE_HZ, BURST = 200.0, 400  # lines a peer may send per second on average, and at once (then: a flood)

# the classes the node reads and writes (their Java names)
PARAM_REQ, PARAM_RSP = "org.arl.fjage.param.ParameterReq", "org.arl.fjage.param.ParameterRsp"
DATAGRAM_REQS = ("org.arl.unet.DatagramReq", "org.arl.unet.phy.TxFrameReq")
ADDRESS_REQ, ADDRESS_RSP = "org.arl.unet.addr.AddressResolutionReq", "org.arl.unet.addr.AddressResolutionRsp"
MESSAGE, REFUSE_RSP = "org.arl.fjage.Message", "org.arl.unet.RefuseRsp"
PARAM_GROUPS = {
    "node": "org.arl.unet.nodeinfo.NodeInfoParam",
    "phy": "org.arl.unet.phy.PhysicalParam",
    "phy[]": "org.arl.unet.phy.PhysicalChannelParam",
    "datagram": "org.arl.unet.DatagramParam",
}


@dataclass
class Datagram:
    """What a peer asked an agent to send (hilgate's addresses: ``to`` 255 is broadcast)."""

    agent: str
    client: Any
    msg_id: str
    requester: str
    data: bytes
    to: int
    protocol: int
    reliable: bool
    done: bool = False  # its fate was told: nothing more is said of it


class NodeHost(Protocol):
    """What the node needs of whoever serves it (the UnetStack door, the emulated modem)."""

    node_name: str

    @property
    def address(self) -> int: ...

    def now(self) -> float:
        """Model seconds since the run began."""

    def phy_params(self) -> dict[str, Any]:
        """``MTU`` (bytes), ``dataRate`` (bit/s), ``frameDuration`` (s of an MTU), ``busy``."""

    def set_address(self, address: int) -> bool:
        """Answer to ``address`` from now on; False when the node's address is not the host's to change."""

    def transmit(self, datagram: Datagram) -> str | None:
        """Send it; the reason it cannot go (a refusal), or None and its fate told later."""

    def resolve(self, name: str) -> int | None:
        """The address of the node called ``name`` on the channel, None if unknown."""

    def hold(self, client: Any) -> None:
        """The peer has asked something: what the node says to it next waits a moment (the host's
        answer delay), in order."""

    def write(self, client: Any, data: bytes) -> bool:
        """Bytes to a peer; False when it could not take them (it is being closed)."""

    def close_client(self, client: Any) -> None: ...

    def refused(self, cause: str) -> None:
        """The node refused something a peer said (``cause``): counted and traced where the host keeps such."""


@dataclass
class _Peer:
    codec: FjageCodec = field(default_factory=FjageCodec)
    wants: set[str] = field(default_factory=set)
    tokens: float = float(BURST)
    stamp: float = 0.0


def to_unet(address: int) -> int:
    return UNET_BROADCAST if address == HILGATE_BROADCAST else address


def from_unet(address: int) -> int:
    return HILGATE_BROADCAST if address == UNET_BROADCAST else address


# -- parameters ------------------------------------------------------------------------------------


def agent_params(host: NodeHost, agent: str, index: int) -> tuple[dict[str, Any], set[str]]:
    """(qualified name → value, the writable ones) of ``agent`` (``index`` ≥ 0: per frame type), read from
    ``host``: the table of what each agent shows, apart from :class:`UnetNode`, which answers the requests."""
    if agent == "node":
        group = PARAM_GROUPS["node"]
        values = {"address": to_unet(host.address), "nodeName": host.node_name, "addressSize": 8,
                  "time": round(host.now() * 1e6), "canForward": False, "mobility": False}
        return {f"{group}.{k}": v for k, v in values.items()}, {f"{group}.address"}
    if agent in DATAGRAM_AGENTS:
        phy = host.phy_params()
        mtu = {f"{PARAM_GROUPS['datagram']}.MTU": phy["MTU"], f"{PARAM_GROUPS['datagram']}.RTU": phy["MTU"]}
        if agent == "uwlink":
            return mtu, set()
        if index in (1, DATA_FRAME):
            group = PARAM_GROUPS["phy[]"]
            values = {"MTU": phy["MTU"], "frameLength": phy["MTU"], "dataRate": phy["dataRate"],
                      "frameDuration": phy["frameDuration"]}
            return {f"{group}.{k}": v for k, v in values.items()}, set()
        group = PARAM_GROUPS["phy"]
        values = {"time": round(host.now() * 1e6), "busy": phy["busy"], "rxEnable": True}
        return {**mtu, **{f"{group}.{k}": v for k, v in values.items()}}, set()
    return {}, set()


def _asked(data: dict) -> list[tuple[str, Any, bool]]:
    """The parameters a ``ParameterReq`` names, one (``param``) or many (``requests``): (name, value, is a
    set), in its order."""
    asked: list[tuple[str, Any, bool]] = []
    if isinstance(data.get("param"), str):
        asked.append((data["param"], data.get("value"), data.get("value") is not None))
    for item in data.get("requests") or []:
        if isinstance(item, dict) and isinstance(item.get("param"), str):
            asked.append((item["param"], item.get("value"), item.get("value") is not None))
    return asked


class UnetNode:
    """The agents of one node, shared by every peer connected to it (the module's docstring)."""

    def __init__(self, host: NodeHost, clock: Callable[[], float] = time.monotonic):
        self.host = host
        self.clock = clock
        self.peers: dict[Any, _Peer] = {}
        self.refused: Counter[str] = Counter()
        self.address_seen = host.address

    # -- peers --------------------------------------------------------------------------------------

    def connect(self, client: Any) -> None:
        self.peers[client] = _Peer(stamp=self.clock())

    def leave(self, client: Any) -> None:
        self.peers.pop(client, None)

    def receive(self, client: Any, data: bytes) -> None:
        """A peer's bytes: answered, acted on, or refused (then, for broken framing, the peer is closed)."""
        peer = self.peers.get(client)
        if peer is None:
            return
        for event in peer.codec.receive_data(data):
            if client not in self.peers:
                return
            if not self._take_token(peer):
                self._refuse(client, "flood", f"more than {BURST:.0f} lines at once or {RATE_HZ:.0f} a second",
                             close=True)
                return
            match event:
                case Request():
                    self.host.hold(client)
                    self._write(client, fjage.encode(self._answer(event)))
                case Deliver(message=msg):
                    if msg["data"].get("perf") == "REQUEST":
                        self.host.hold(client)
                    self._deliver(client, msg)
                case Wants(agent_ids=ids):
                    peer.wants = set(ids)
                case Alive(value=True):
                    self._write(client, fjage.encode({"alive": True}))
                case Alive():
                    pass  # the peer is leaving: its end of file closes it
                case Response():
                    pass  # an answer to nothing the node asked
                case Bad(reason=reason, fatal=True):
                    cause = "long_line" if "longer than" in reason else "bad_json"
                    self._refuse(client, cause, reason, close=True)
                    return
                case Bad(reason=reason, id=ident, action=action):
                    cause = "unknown_action" if reason.startswith("unknown action") else "bad_message"
                    self._refuse(client, cause, reason, ident=ident, action=action)

    def _take_token(self, peer: _Peer) -> bool:
        now = self.clock()
        peer.tokens = min(float(BURST), peer.tokens + (now - peer.stamp) * RATE_HZ)
        peer.stamp = now
        if peer.tokens < 1.0:
            return False
        peer.tokens -= 1.0
        return True

    def _refuse(self, client: Any, cause: str, reason: str, close: bool = False, ident: str | None = None,
                action: str | None = None) -> None:
        """One refusal: counted by cause, said once to the peer (as the answer to its question, when it
        asked one, so a gateway is not left waiting), logged for the 1st, 2nd, 4th… of a cause."""
        count = self.count(cause)
        if count & (count - 1) == 0:
            log.warning("%s: UnetStack peer refused: %s (%d refused so far for this cause)",
                        self.host.node_name, reason, count)
        answer: dict[str, Any] = {"error": reason}
        if ident is not None:
            answer = {"id": ident, "inResponseTo": action or "", "error": reason}
        self.host.write(client, fjage.encode(answer))
        if close:
            self.peers.pop(client, None)
            self.host.close_client(client)

    def count(self, cause: str) -> int:
        """One more refusal of ``cause``: counted here and by the host (the link's trace and status)."""
        self.refused[cause] += 1
        self.host.refused(cause)
        return self.refused[cause]

    def _write(self, client: Any, data: bytes) -> None:
        if not self.host.write(client, data):
            self.leave(client)

    # -- the directory --------------------------------------------------------------------------------

    def _answer(self, request: Request) -> dict:
        answer: dict[str, Any] = {"id": request.id, "inResponseTo": request.action}
        body = request.body
        if request.action == "agents":
            answer["agentIDs"] = list(AGENTS)
        elif request.action == "containsAgent":
            answer["answer"] = fjage.agent_name(body.get("agentID")) in AGENTS
        elif request.action == "services":
            answer["services"] = sorted({SERVICE + s for services in AGENTS.values() for s in services})
        else:
            service = body.get("service")
            providers = [name for name, services in AGENTS.items()
                         if isinstance(service, str) and service.startswith(SERVICE)
                         and service[len(SERVICE):] in services]
            if request.action == "agentsForService":
                answer["agentIDs"] = providers
            elif providers:
                answer["agentID"] = providers[0]
            # (none: no agentID at all; a gateway reads a null one as a broken answer and waits)
        return answer

    # -- messages -------------------------------------------------------------------------------------

    def _deliver(self, client: Any, msg: dict) -> None:
        data = msg["data"]
        recipient = fjage.agent_name(data.get("recipient"))
        if recipient in AGENTS:
            self._to_agent(client, recipient, msg)
            return
        others = [peer for peer, state in self.peers.items() if peer is not client and recipient in state.wants]
        for other in others:  # a container passes a message on to whoever wants it
            self._write(other, fjage.send(msg))
        if not others and data.get("perf") == "REQUEST":
            self._reply(client, data, MESSAGE, "FAILURE", sender=recipient or "?")
            self.count("no_agent")

    def _reply(self, client: Any, request: dict, clazz: str, perf: str, sender: str | None = None,
               **fields: Any) -> None:
        requester = fjage.agent_name(request.get("sender"))
        msg = fjage.message(clazz, perf, sender or str(request.get("recipient")), requester,
                            request.get("msgID") if isinstance(request.get("msgID"), str) else None, **fields)
        self._write(client, fjage.send(msg))

    def _to_agent(self, client: Any, agent: str, msg: dict) -> None:
        clazz, data = msg["clazz"], msg["data"]
        if clazz == PARAM_REQ:
            self._parameters(client, agent, data)
        elif clazz in DATAGRAM_REQS and agent in DATAGRAM_AGENTS:
            self._datagram(client, agent, clazz, data)
        elif clazz == ADDRESS_REQ and agent == "arp":
            name = data.get("name")
            address = self.host.resolve(name) if isinstance(name, str) else None
            if address is None:
                self._reply(client, data, REFUSE_RSP, "REFUSE", reason=f"unknown node {str(name)[:100]!r}")
            else:
                self._reply(client, data, ADDRESS_RSP, "INFORM", name=name, address=to_unet(address))
        elif data.get("perf") == "REQUEST":
            self.count("not_understood")
            self._reply(client, data, MESSAGE, "NOT_UNDERSTOOD")

    # -- parameters ----------------------------------------------------------------------------------

    def _parameters(self, client: Any, agent: str, data: dict) -> None:
        index = data.get("index", -1)
        index = index if type(index) is int else -1
        asked = _asked(data)
        params, writable = agent_params(self.host, agent, index)
        if asked:
            by_short = {fjage.short_name(name): name for name in params}
            for name, value, is_set in asked:
                full = name if name in params else by_short.get(fjage.short_name(name))
                if full is not None and is_set and full in writable:
                    self._set(agent, full, value)
            params, writable = agent_params(self.host, agent, index)
            names = [name if name in params else by_short.get(fjage.short_name(name)) for name, _, _ in asked]
            chosen = {full: params[full] for full in names if full is not None}
        else:
            chosen = params
        fields: dict[str, Any] = {"index": index, "readonly": [n for n in chosen if n not in writable]}
        items = list(chosen.items())
        if items:
            fields["param"], fields["value"] = items[0]
            fields["values"] = dict(items[1:])
        self._reply(client, data, PARAM_RSP, "INFORM", sender=agent, **fields)
        self.address_changed()

    def _set(self, agent: str, name: str, value: Any) -> None:
        if agent == "node" and name.endswith(".address") and type(value) is int and 1 <= value <= 254:
            self.host.set_address(value)  # (told to the peers once the answer is out: _parameters)

    def address_changed(self) -> None:
        """The node's address changed (set by a peer, or the link's by a reload): every peer that wants
        parameter changes is told (``ParamChangeNtf``), once."""
        address = self.host.address
        if address == self.address_seen:
            return
        self.address_seen = address
        ntf = fjage.message("org.arl.unet.ParamChangeNtf", "INFORM", "node", PARAMCHANGE,
                            paramValues={f"{PARAM_GROUPS['node']}.address": to_unet(address)})
        self.publish(ntf, (PARAMCHANGE, fjage.topic("node")))

    # -- datagrams -----------------------------------------------------------------------------------

    def _datagram(self, client: Any, agent: str, clazz: str, data: dict) -> None:
        payload = fjage.decode_bytes(data.get("data"))
        to = data.get("to", UNET_BROADCAST)
        protocol = data.get("protocol", 0)
        reliable = data.get("reliability") is True
        mtu = self.host.phy_params()["MTU"]
        if payload is None:
            reason = "data is no byte array"
        elif type(to) is not int or not 0 <= to <= 255:
            reason = f"to {str(to)[:40]} is no address (0-255)"
        elif type(protocol) is not int or not 0 <= protocol <= MAX_PROTOCOL:
            reason = f"protocol {str(protocol)[:40]} is not 0-{MAX_PROTOCOL}"
        elif len(payload) > mtu:
            reason = f"{len(payload)} bytes exceed the MTU ({mtu})"
        elif reliable and agent == "phy":
            reason = "the physical agent does not send reliably (use the link agent)"
        elif reliable and to == UNET_BROADCAST:
            reason = "a broadcast cannot be sent reliably"
        else:
            reason = None
        msg_id = data.get("msgID") if isinstance(data.get("msgID"), str) else ""
        requester = fjage.agent_name(data.get("sender")) or ""
        if reason is None:
            datagram = Datagram(agent, client, msg_id, requester, payload, from_unet(to), protocol, reliable)
            reason = self.host.transmit(datagram)
        if reason is not None:
            self.count("datagram")
            self._reply(client, data, REFUSE_RSP, "REFUSE", sender=agent, reason=reason)
            return
        self._reply(client, data, MESSAGE, "AGREE", sender=agent)

    def _notify(self, datagram: Datagram, clazz: str, perf: str = "INFORM", **fields: Any) -> None:
        if datagram.done or datagram.client not in self.peers:
            return
        msg = fjage.message(clazz, perf, datagram.agent, datagram.requester, datagram.msg_id or None, **fields)
        self._write(datagram.client, fjage.send(msg))

    def transmitted(self, datagram: Datagram, start: float) -> None:
        """On air from ``start`` (model s): the requester is told (a reliable one waits for its acknowledgement)."""
        if datagram.reliable:
            return
        if datagram.agent == "phy":
            self._notify(datagram, "org.arl.unet.phy.TxFrameNtf", txTime=round(start * 1e6), type=DATA_FRAME)
        else:
            self._notify(datagram, "org.arl.unet.DatagramTransmissionNtf", txTime=round(start * 1e6))
        datagram.done = True

    def delivered(self, datagram: Datagram) -> None:
        self._notify(datagram, "org.arl.unet.DatagramDeliveryNtf", to=to_unet(datagram.to))
        datagram.done = True

    def failed(self, datagram: Datagram, reason: str) -> None:
        self._notify(datagram, "org.arl.unet.DatagramFailureNtf", "FAILURE", to=to_unet(datagram.to), reason=reason)
        datagram.done = True

    def received(self, agent: str, src: int, dst: int, protocol: int, data: bytes, rx_time: float,
                 rssi: float | None = None) -> int:
        """A frame the link heard, published on ``agent``'s topic (one for another node on its SNOOP
        sub-topic, as UnetStack's physical agent does); how many peers were given it."""
        fields: dict[str, Any] = {"from": to_unet(src), "to": to_unet(dst), "protocol": protocol,
                                  "data": fjage.encode_bytes(data), "ttl": 0}
        if agent == "phy":
            fields.update(type=DATA_FRAME, rxTime=round(rx_time * 1e6))
            if rssi is not None:
                fields["rssi"] = round(rssi, 1)
            clazz = "org.arl.unet.phy.RxFrameNtf"
        else:
            clazz = "org.arl.unet.DatagramNtf"
        mine = dst in (HILGATE_BROADCAST, self.host.address)
        where = fjage.topic(agent) if mine else f"#{agent}__snoop__ntf"
        return self.publish(fjage.message(clazz, "INFORM", agent, where, **fields), (where,))

    def publish(self, msg: dict, topics: tuple[str, ...]) -> int:
        """``msg`` to every peer that wants one of ``topics`` (once, addressed to the first it wants)."""
        given = 0
        for client, peer in list(self.peers.items()):
            wanted = next((t for t in topics if t in peer.wants), None)
            if wanted is None:
                continue
            msg["data"]["recipient"] = wanted
            self._write(client, fjage.send(msg))
            given += 1
        return given
