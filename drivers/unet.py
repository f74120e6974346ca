"""``backend: unet``: a real UnetStack modem (Subnero's, or any UnetStack node) behind a link id, through its
fjåge API over TCP.

The driver is a gateway, as ``fjagepy``'s is, speaking fjåge's JSON protocol (:mod:`hilgate.core.fjage`,
sans I/O) on the modem's port (``modem_host``, ``port``: 1100 by default), reconnected with backoff by the
port (:mod:`.port`) when the line drops.  At start, and after every reconnection, it:

1. finds the node-info agent (``agentForService NODE_INFO``) and sets the modem's ``address`` to the
   link's (a ``ParameterReq``; the modem's answer is checked and traced);
2. subscribes to the topics of every agent that offers the ``DATAGRAM`` service (``wantsMessagesFor``);
3. picks the agent its frames go through as ``UnetSocket`` does, the link agent first (``LINK``, then
   ``PHYSICAL``, then any ``DATAGRAM`` agent), and says the link is up.

A GLI frame then goes as one ``DatagramReq`` of the link's ``unet_protocol`` to the frame's destination
(hilgate's broadcast, 255, is UnetStack's 0), one at a time: the modem AGREEs or refuses it (dropped,
counted and traced with the modem's reason), and its ``TxFrameNtf``/``DatagramTransmissionNtf`` (or a
delivery or failure notification) ends it; a modem that says nothing within ``send_timeout_s`` has it
counted as sent and traced (``no_tx_report``).  A frame the modem had not answered for when the line
dropped goes again, first, after the reconnection: what the driver queued is not lost (up to
``queue_frames`` while the modem is away).  Received ``DatagramNtf``/``RxFrameNtf`` of the link's protocol,
for the link's address or broadcast, are parsed as one frame of the link's packet class (a ``raw`` link
takes the bytes as they are); bytes that make none are counted and traced (``not_a_frame``).
"""

from __future__ import annotations

import logging
import uuid
from typing import Any, Callable

from hilgate.core import fjage
from hilgate.core.backend import AppFrame, QueuedBackend
from hilgate.core.packets import BROADCAST, PacketClass, PacketError, Raw
from hilgate.core.unet_node import from_unet, to_unet

from .port import Port
from .table import UNET_LIMITS, UnetOptions

log = logging.getLogger(__name__)

SERVICE = "org.arl.unet.Services."
PROVIDERS = ("LINK", "PHYSICAL", "DATAGRAM")  # the agent frames go through: UnetSocket's order, below transport
DONE = {"org.arl.unet.phy.TxFrameNtf", "org.arl.unet.DatagramTransmissionNtf", "org.arl.unet.DatagramDeliveryNtf"}
FAILED = {"org.arl.unet.DatagramFailureNtf"}
RECEIVED = {"org.arl.unet.DatagramNtf", "org.arl.unet.phy.RxFrameNtf"}
RESTART_S = 2.0  # after a start-up the modem did not answer, the next try

Answer = Callable[[Any], Any]  # a Response's body, a reply message's data, or None (timed out)


class UnetBackend(QueuedBackend):
    kind = "unet"

    def __init__(self, link_id: str, address: int, packet: PacketClass, options: UnetOptions, scheduler: Any,
                 trace: Callable[[dict], Any]):
        super().__init__(link_id, scheduler, trace, options.queue_frames)
        self.address = address
        self.packet = packet
        self.options = options
        self.codec = fjage.FjageCodec()
        self.aid = f"hilgate-{link_id[:40]}-{uuid.uuid4().hex[:8]}"
        self.waiting: dict[str, tuple[Answer, Any]] = {}  # id or msgID asked → (what to do, its timer)
        self.provider: str | None = None
        self.inflight: tuple[AppFrame, str] | None = None  # the frame the modem has, and its msgID
        self.restart_timer = None
        self.port = Port(f"socket://{options.modem_host}:{options.port}", scheduler, self._on_data, self._on_port,
                         name=link_id)
        self.port.open()

    @property
    def idle(self) -> bool:
        return not self.queue and self.inflight is None

    def admit(self, frame: AppFrame) -> None:
        (self.options.limits or UNET_LIMITS).admit(len(frame.real), "datagram")

    def send(self, frame: AppFrame) -> bool:
        self.admit(frame)
        return super().send(frame)

    def close(self) -> None:
        self._forget()
        self.port.close()
        if self.inflight is not None:  # not answered for: dropped with the queue, counted (closed)
            self.queue.appendleft(self.inflight[0])
            self.inflight = None
        super().close()

    # -- the line -----------------------------------------------------------------------------------------

    def _write(self, obj: dict) -> None:
        self.port.write(fjage.encode(obj))

    def _forget(self) -> None:
        for _, timer in self.waiting.values():
            self.scheduler.cancel(timer)
        self.waiting.clear()
        self.scheduler.cancel(self.restart_timer)
        self.restart_timer = None

    def _on_port(self, up: bool, reason: str | None) -> None:
        self._forget()
        self.codec = fjage.FjageCodec()
        self.provider = None
        if self.inflight is not None:  # the modem may not have it: it goes again, first
            self.queue.appendleft(self.inflight[0])
            self.inflight = None
        if up:
            self.set_state("starting")
            self._start()
        else:
            self.set_state("down", reason)

    def _ask(self, key: str, obj: dict, then: Answer, timeout: float | None = None) -> None:
        timer = self.scheduler.after_wall(timeout or self.options.command_timeout_s, self._timed_out, key)
        self.waiting[key] = (then, timer)
        self._write(obj)

    def _timed_out(self, key: str) -> None:
        entry = self.waiting.pop(key, None)
        if entry is not None:
            entry[0](None)

    def _action(self, action: str, then: Answer, **fields: Any) -> None:
        ident = str(uuid.uuid4())
        self._ask(ident, {"id": ident, "action": action, **fields}, then)

    def _request(self, clazz: str, recipient: str, then: Answer, timeout: float | None = None,
                 **fields: Any) -> str:
        msg = fjage.message(clazz, "REQUEST", self.aid, recipient, **fields)
        msg_id = msg["data"]["msgID"]
        timer = self.scheduler.after_wall(timeout or self.options.command_timeout_s, self._timed_out, msg_id)
        self.waiting[msg_id] = (then, timer)
        self._write({"action": "send", "relay": False, "message": msg})
        return msg_id

    def _settle(self, key: str, value: Any) -> None:
        entry = self.waiting.pop(key, None)
        if entry is not None:
            self.scheduler.cancel(entry[1])
            entry[0](value)

    def _on_data(self, data: bytes) -> None:
        for event in self.codec.receive_data(data):
            match event:
                case fjage.Response(id=ident, body=body):
                    self._settle(ident, body)
                case fjage.Deliver(message=msg):
                    self._message(msg)
                case fjage.Alive(value=True):
                    self._write({"alive": True})
                case fjage.Request(id=ident, action=action):
                    self._write({"id": ident, "inResponseTo": action, **self._directory(action)})
                case fjage.Bad(reason=reason, fatal=fatal):
                    self.event("err", cause="modem_protocol", reason=reason[:200])
                    if fatal:
                        log.warning("%s: the modem broke fjåge's framing (%s): reconnecting", self.link_id, reason)
                        self.codec = fjage.FjageCodec()

    def _directory(self, action: str) -> dict:
        """What the driver, a gateway, answers a container that asks about it (as fjagepy does)."""
        return {"agents": {"agentIDs": [self.aid]}, "containsAgent": {"answer": False},
                "services": {"services": []}, "agentsForService": {"agentIDs": []}}.get(action, {})

    # -- start-up -------------------------------------------------------------------------------------------

    def _start(self) -> None:
        self._write({"action": "wantsMessagesFor", "agentIDs": [self.aid]})
        self._action("agentForService", self._node_found, service=SERVICE + "NODE_INFO")

    def _failed_start(self, what: str) -> None:
        reason = f"the modem did not {what}"
        log.warning("%s: %s; trying again in %g s", self.link_id, reason, RESTART_S)
        self.set_state("starting", reason)
        self.restart_timer = self.scheduler.after_wall(RESTART_S, self._restart)

    def _restart(self) -> None:
        self.restart_timer = None
        if self.port.up:
            self._start()

    def _node_found(self, body: dict | None) -> None:
        if body is None:
            self._failed_start("answer agentForService(NODE_INFO)")
            return
        node = fjage.agent_name(body.get("agentID")) or "node"
        self._request("org.arl.fjage.param.ParameterReq", node, self._address_set, index=-1, requests=[],
                      param="address", value=to_unet(self.address))

    def _address_set(self, reply: dict | None) -> None:
        if reply is None:
            self._failed_start("answer the address it was given")
            return
        value = reply.get("value")
        self.event("modem_config", param="address", value=value, asked=self.address)
        if value != to_unet(self.address):
            log.warning("%s: the modem's address is %s, not the link's %d", self.link_id, value, self.address)
        self._action("agentsForService", self._datagram_agents, service=SERVICE + "DATAGRAM")

    def _datagram_agents(self, body: dict | None) -> None:
        if body is None:
            self._failed_start("answer agentsForService(DATAGRAM)")
            return
        agents = [a for a in body.get("agentIDs") or [] if fjage.agent_name(a)]
        self._write({"action": "wantsMessagesFor", "agentIDs": [self.aid, *(fjage.topic(a) for a in agents)]})
        self._provider(0)

    def _provider(self, n: int) -> None:
        if n >= len(PROVIDERS):
            self._failed_start("name an agent for datagrams")
            return

        def found(body: dict | None) -> None:
            agent = fjage.agent_name(body.get("agentID")) if body is not None else None
            if body is None:
                self._failed_start(f"answer agentForService({PROVIDERS[n]})")
            elif agent is None:
                self._provider(n + 1)
            else:
                self.provider = agent
                log.info("%s: UnetStack modem at %s:%d up, address %d, frames through %s (protocol %d)",
                         self.link_id, self.options.modem_host, self.options.port, self.address, agent,
                         self.options.unet_protocol)
                self.set_state("up")
                self.pump()
                if self.on_idle is not None:
                    self.on_idle()

        self._action("agentForService", found, service=SERVICE + PROVIDERS[n])

    # -- frames out -----------------------------------------------------------------------------------------

    def pump(self) -> None:
        if self._state != "up" or self.inflight is not None or not self.queue or self.provider is None:
            return
        frame = self.queue.popleft()
        msg_id = self._request("org.arl.unet.DatagramReq", self.provider, lambda reply: self._agreed(frame, reply),
                               data=list(frame.real), to=to_unet(frame.dst), protocol=self.options.unet_protocol)
        self.inflight = (frame, msg_id)

    def _agreed(self, frame: AppFrame, reply: dict | None) -> None:
        if self.inflight is None or self.inflight[0] is not frame:
            return
        if reply is None:  # a modem that does not answer: the line is as good as gone
            log.warning("%s: the modem did not answer a datagram request: restarting", self.link_id)
            self.queue.appendleft(frame)
            self.inflight = None
            self._forget()
            self.set_state("starting", "the modem did not answer a datagram request")
            self._start()
            return
        if reply.get("perf") != "AGREE":
            self._finish(frame, f"refused: {str(reply.get('reason') or reply.get('perf'))[:200]}")
            return
        msg_id = self.inflight[1]
        timer = self.scheduler.after_wall(self.options.send_timeout_s, self._timed_out, msg_id)
        self.waiting[msg_id] = (lambda ntf: self._transmitted(frame, ntf), timer)

    def _transmitted(self, frame: AppFrame, ntf: dict | None) -> None:
        if self.inflight is None or self.inflight[0] is not frame:
            return
        if ntf is None:
            self.event("err", cause="no_tx_report", dst=frame.dst, size=len(frame.real))
            self._finish(frame, None)
        elif ntf.get("_clazz") in FAILED:
            self._finish(frame, f"failed: {str(ntf.get('reason'))[:200]}")
        else:
            self._finish(frame, None)

    def _finish(self, frame: AppFrame, failure: str | None) -> None:
        self.inflight = None
        if failure is None:
            self.tx_packets += 1
        else:
            self.drop(frame, "refused" if failure.startswith("refused") else "failed")
            self.event("err", cause="modem", reason=failure, dst=frame.dst)
        self.pump()
        if self.idle and self.on_idle is not None:
            self.on_idle()

    # -- messages in ----------------------------------------------------------------------------------------

    def _message(self, msg: dict) -> None:
        clazz, data = msg["clazz"], msg["data"]
        reply_to = data.get("inReplyTo")
        if isinstance(reply_to, str) and reply_to in self.waiting:
            self._settle(reply_to, {**data, "_clazz": clazz})
            return
        if clazz in RECEIVED:
            self._received(data)

    def _received(self, data: dict) -> None:
        if data.get("protocol", 0) != self.options.unet_protocol:
            return  # another protocol's datagram: another application's, not this link's
        src, dst = data.get("from"), data.get("to", 0)
        payload = fjage.decode_bytes(data.get("data"))
        if payload is None or type(src) is not int or type(dst) is not int:
            self.event("err", cause="modem_protocol", reason="a datagram notification without from, to and bytes")
            return
        dst = from_unet(dst)
        if dst not in (BROADCAST, self.address):
            return
        if isinstance(self.packet, Raw):
            real, body, fsrc, fdst = payload, payload, None, None
        else:
            try:
                real, body, fsrc, fdst = self.packet.parse_real(payload)
            except PacketError as exc:
                self.event("err", cause="not_a_frame", reason=exc.reason, size=len(payload), src=src)
                return
        self.rx_packets += 1
        frame = AppFrame(real, body, self.packet, 0, from_unet(src) if fsrc is None else fsrc,
                         dst if fdst is None else fdst, self.scheduler.now())
        if self.on_receive is not None:
            self.on_receive(frame)
