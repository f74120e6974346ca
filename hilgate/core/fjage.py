"""fjåge's JSON protocol, without I/O: what a UnetStack node and the programs that drive it say to each other.

A UnetStack node (a Subnero modem, UnetStack's simulator) serves its agents to other containers and to
gateways (``fjagepy``'s ``Gateway``, ``unetpy``'s ``UnetSocket``, the Java and JavaScript gateways) as
lines of JSON over TCP: a *request* ``{"id", "action", …}`` (``agents``, ``containsAgent``,
``services``, ``agentForService``, ``agentsForService``) is answered ``{"id", "inResponseTo", …}``;
``{"action": "send", "message": {"clazz", "data"}}`` carries a message between agents either way;
``wantsMessagesFor`` says whose messages (the gateway's own id, the topics it subscribed to) it wants;
``{"alive": …}`` keeps the line alive or says goodbye.  The public references are fjåge's
documentation ("JSON protocol") and the gateways' sources; nothing here is copied from them.

Both ends of hilgate use this one module: the UnetStack door and the emulated UnetStack modem serve a
node (:mod:`hilgate.core.unet_node`), and the ``unet`` driver is a gateway to a real modem.  So the codec
turns a peer's bytes into events (:class:`Request`, :class:`Deliver`, :class:`Wants`, :class:`Alive`,
:class:`Response`, :class:`Bad`) and the helpers below turn messages into bytes; the caller owns the
socket.  A line is bounded (:data:`MAX_LINE`) and parsed by :func:`hilgate.core.safejson.loads`, so
no peer's bytes cost a traceback: what cannot be read is a :class:`Bad` with one line saying why.

Byte arrays: the Java side writes a ``byte[]`` as ``{"clazz": "[B", "data": <base64>}`` and fjagepy reads
that as signed bytes; gateways write plain lists of integers.  :func:`decode_bytes` takes both (signed or
not), :func:`encode_bytes` writes the Java form, as a real node does.
"""

from __future__ import annotations

import base64
import binascii
import json
import uuid
from dataclasses import dataclass
from typing import Any

from .safejson import JsonError, loads

__all__ = ["MAX_LINE", "ACTIONS", "Request", "Deliver", "Wants", "Alive", "Response", "Bad", "FjageCodec",
           "message", "encode", "encode_bytes", "decode_bytes", "agent_name", "topic", "short_name"]

MAX_LINE = 256 * 1024
"""The longest line a peer may send (bytes): a 16 KiB datagram as a list of integers takes 64 KiB; a
longer line is refused, not buffered without end."""

ACTIONS = ("agents", "containsAgent", "services", "agentForService", "agentsForService")
"""The directory actions a node answers (``send``, ``wantsMessagesFor`` and ``shutdown`` are not questions)."""


@dataclass(frozen=True)
class Request:
    """A directory question (one of :data:`ACTIONS`): its ``id`` comes back in the answer."""

    id: str
    action: str
    body: dict


@dataclass(frozen=True)
class Deliver:
    """``send``: a message (``{"clazz", "data"}``) for an agent or a topic; ``relay`` as the peer gave it."""

    message: dict
    relay: bool


@dataclass(frozen=True)
class Wants:
    """``wantsMessagesFor``: the agent ids and topics (``#name``) the peer wants messages for, from now on."""

    agent_ids: tuple[str, ...]


@dataclass(frozen=True)
class Alive:
    """``{"alive": true}`` (a keep-alive, answered in kind) or ``false`` (the peer is leaving)."""

    value: bool


@dataclass(frozen=True)
class Response:
    """An answer to a question this end asked (``inResponseTo``): what a gateway reads."""

    id: str
    action: str
    body: dict


@dataclass(frozen=True)
class Bad:
    """A line that is no fjåge message: ``fatal`` when the framing itself is gone (an over-long line, bytes
    that are not UTF-8 JSON), else an object this end cannot act on (an unknown action, a field of the
    wrong type).  ``reason`` is one line; ``id`` and ``action`` are the line's, when it had them."""

    reason: str
    fatal: bool
    id: str | None = None
    action: str | None = None


Event = Request | Deliver | Wants | Alive | Response | Bad


class FjageCodec:
    """One peer's side of the line: bytes in, events out (``receive_data``).  After a fatal :class:`Bad`
    the codec takes nothing more (the caller refuses once and closes)."""

    def __init__(self, max_line: int = MAX_LINE):
        self.max_line = max_line
        self.buffer = bytearray()
        self.broken = False

    @property
    def pending(self) -> int:
        """Bytes of a line not yet ended."""
        return len(self.buffer)

    def receive_data(self, data: bytes) -> list[Event]:
        if self.broken:
            return []
        self.buffer += data
        events: list[Event] = []
        while True:
            end = self.buffer.find(b"\n")
            if end < 0:
                if len(self.buffer) > self.max_line:
                    self._break()
                    events.append(Bad(f"a line longer than {self.max_line} bytes", True))
                return events
            line = bytes(self.buffer[:end]).strip()
            del self.buffer[:end + 1]
            if len(line) > self.max_line:
                self._break()
                events.append(Bad(f"a line longer than {self.max_line} bytes", True))
                return events
            if not line:
                continue
            event = self._event(line)
            events.append(event)
            if isinstance(event, Bad) and event.fatal:
                self._break()
                return events

    def _break(self) -> None:
        self.broken = True
        self.buffer.clear()

    def _event(self, line: bytes) -> Event:
        try:
            obj = loads(line, max_bytes=self.max_line)
        except JsonError as exc:
            return Bad(str(exc), True)
        if not isinstance(obj, dict):
            return Bad(f"a JSON {type(obj).__name__}, not an object", True)
        ident = obj.get("id")
        ident = ident if isinstance(ident, str) and len(ident) <= 200 else None
        if "alive" in obj and "action" not in obj:
            return Alive(obj["alive"] is True)
        if "inResponseTo" in obj:
            answered = obj["inResponseTo"]
            if ident is None or not isinstance(answered, str):
                return Bad("an answer without a string id and inResponseTo", False)
            return Response(ident, answered, obj)
        return _action(obj, ident)


def _action(obj: dict, ident: str | None) -> Event:
    """A line that asks something of the gateway (``action``: send, wantsMessagesFor, or one of ACTIONS)
    as its event, or Bad naming what it lacks."""
    action = obj.get("action")
    if not isinstance(action, str):
        return Bad("no action", False, ident)
    action_name = action[:60]
    if action == "send":
        msg = obj.get("message")
        if not (isinstance(msg, dict) and isinstance(msg.get("clazz"), str) and isinstance(msg.get("data"), dict)):
            return Bad("send without a message {clazz, data}", False, ident, action_name)
        return Deliver(msg, obj.get("relay") is True)
    if action == "wantsMessagesFor":
        ids = obj.get("agentIDs")
        if not isinstance(ids, list) or not all(isinstance(a, str) for a in ids):
            return Bad("wantsMessagesFor without a list of agent ids", False, ident, action_name)
        return Wants(tuple(ids))
    if action in ACTIONS:
        if ident is None:
            return Bad(f"{action} without a string id", False, None, action_name)
        return Request(ident, action, obj)
    return Bad(f"unknown action {action_name!r}", False, ident, action_name)


# -- writing --------------------------------------------------------------------------------------------


def encode(obj: dict) -> bytes:
    """One line of the protocol."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode() + b"\n"


def message(clazz: str, perf: str, sender: str, recipient: str | None, in_reply_to: str | None = None,
            **fields: Any) -> dict:
    """A message as fjåge writes one (``clazz``: its Java class; ``perf``: REQUEST, AGREE, INFORM…)."""
    data = {"msgID": str(uuid.uuid4()), "perf": perf, "sender": sender}
    if recipient is not None:
        data["recipient"] = recipient
    if in_reply_to is not None:
        data["inReplyTo"] = in_reply_to
    data.update(fields)
    return {"clazz": clazz, "data": data}


def send(msg: dict, relay: bool = False) -> bytes:
    """``msg`` as a ``send`` action (what a node writes to a gateway that wants it)."""
    return encode({"action": "send", "relay": relay, "message": msg})


def encode_bytes(data: bytes) -> dict:
    """A byte array as a Java node writes it."""
    return {"clazz": "[B", "data": base64.b64encode(data).decode()}


def decode_bytes(value: Any, limit: int = MAX_LINE) -> bytes | None:
    """A byte array as a peer wrote it (Java's base64 form, or a list of integers, signed or not); None if
    ``value`` is neither (or longer than ``limit`` bytes)."""
    if value is None:
        return b""
    if isinstance(value, dict) and value.get("clazz") == "[B" and isinstance(value.get("data"), str):
        try:
            data = base64.b64decode(value["data"], validate=True)
        except (binascii.Error, ValueError):
            return None
        return data if len(data) <= limit else None
    if isinstance(value, list) and len(value) <= limit:
        if all(type(b) is int and -128 <= b <= 255 for b in value):
            return bytes(b & 0xFF for b in value)
    return None


def agent_name(value: Any) -> str | None:
    """An agent id as the protocol writes it (a string; a topic begins with ``#``), else None."""
    return value if isinstance(value, str) and 0 < len(value) <= 200 else None


def topic(name: str) -> str:
    """The topic an agent publishes its notifications on (``#phy__ntf``), as fjåge names it."""
    return f"#{name}__ntf"


def short_name(param: str) -> str:
    """``org.arl.unet.DatagramParam.MTU`` → ``MTU``: gateways ask by either name."""
    return param.rsplit(".", 1)[-1]
