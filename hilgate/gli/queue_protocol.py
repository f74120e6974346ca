"""dccomms' queue protocol, device side, without queues (h11's way): messages in, typed events out;
READY/BUSY out without repeats.

Every message is one type byte and a body: 0 FRAME (the whole fixed buffer of the link's packet
class: real packet, then the 12-byte virtual area), 1 REQ_STATE (empty: "are you ready?"),
2 CMD_STATE (one byte: 0 BUSY, 1 READY), 3 NOTBUILT (internal to dccomms, ignored).  Any message at
all shows that an application is on the link (dccomms applications say REQ_STATE when they start).
Tested without queues (``tests/test_gli_session.py``); :class:`hilgate.gli.queues.MqEndpoint` moves
the bytes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

from ..core.packets import Decoded, PacketClass, PacketError

FRAME, REQ_STATE, CMD_STATE, NOTBUILT = 0, 1, 2, 3
BUSY, READY = 0, 1
FRAME_PREFIX = bytes([FRAME])
STATE_MESSAGES = (bytes([CMD_STATE, BUSY]), bytes([CMD_STATE, READY]))  # (made once: every READY is one of them)


class FrameIn(NamedTuple):
    """A frame from the application (a named tuple, not a frozen dataclass: one is made per frame, and
    it is made in a third of the time)."""

    decoded: Decoded


@dataclass(frozen=True)
class StateRequest:
    pass


@dataclass(frozen=True)
class Refused:
    """A message that cannot be accepted: ``reason`` (``size``, ``type``, a packet error) and its size."""

    reason: str
    size: int


@dataclass(frozen=True)
class Ignored:
    pass


class QueueProtocol:
    def __init__(self, packet: PacketClass):
        self.packet = packet
        self.attended = False      # an application has spoken on the link
        self.said: int | None = None  # the state the application was last told

    def receive(self, message: bytes) -> FrameIn | StateRequest | Refused | Ignored:
        self.attended = True
        if not message:
            return Refused("size", 0)
        kind = message[0]
        if kind == FRAME:
            self.said = BUSY  # dccomms' WritePacket sets the application's own PHY state BUSY
            try:
                return FrameIn(self.packet.decode_body(message[1:]))
            except PacketError as exc:
                return Refused(exc.reason, len(message))
        if kind == REQ_STATE:
            return StateRequest()
        if kind == NOTBUILT:
            return Ignored()
        return Refused("type", len(message))

    @staticmethod
    def state_message(ready: bool) -> bytes:
        return STATE_MESSAGES[READY if ready else BUSY]

    def state_change(self, ready: bool) -> bytes | None:
        """CMD_STATE for ``ready`` if the application has not been told it yet, else None."""
        state = READY if ready else BUSY
        return None if state == self.said else STATE_MESSAGES[state]

    def told(self, message: bytes) -> None:
        """``message`` (a CMD_STATE) reached the application's queue."""
        self.said = message[1]

    def message_of(self, frame: Any) -> bytes | None:
        """The FRAME message of an application's frame (a :class:`~hilgate.core.backend.AppFrame`) in this
        link's packet class; None when it does not fit the class (re-encoded from its payload when the
        sender's class is another).  Built anew from the real packet, never relayed from the sender's
        own message: that was tried (issue 31) and cost more than the one join it saves."""
        packet = self.packet
        real = frame.real
        if frame.packet.name != packet.name:
            try:
                real = packet.encode(frame.payload, src=frame.src, dst=frame.dst)
            except PacketError:
                return None
        return packet.encode_body(real, frame.seq, frame.src, frame.dst, FRAME_PREFIX)
