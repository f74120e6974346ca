"""A Water Linked Modem-M64 in front of a simulated link, on a pseudo-terminal.

``emulate: {protocol: m64, pty: /tmp/ttyM64a, role: a, channel: 3}`` answers there as the modem does
(:mod:`.m64_codec`: ``wcv``, ``wcn``, ``wcc``, ``wcs``, ``wcl``, ``wcf``, ``wcd``, ``wcq``; ``wr?``
and ``wr!`` for what it cannot take) and moves 8-byte packets through the channel model with the
modem's own timing:

- **Slots.** Role A transmits once every :data:`SLOT_S` (the head of its queue, or an all-zero sync
  packet when the queue is empty: it always transmits); role B answers each packet it hears from an A
  once it is in sync, :data:`TURNAROUND_S` after that packet's end, with its own head of queue or a
  sync packet.  So each direction carries about one packet a second (64 bit/s net), as published.
- **Sync.** Water Linked: "The modem with role B will go back to listen mode if several consecutive
  packets from the modem with role A cannot be decoded (i.e. signal is lost)", and a packet that cannot
  be decoded counts in ``pkt_loss_cnt``, "regardless of the packet being … data or a sync packet".  So a
  modem is in sync after a good packet from the other role; while in sync it expects the next one a slot
  after the last one ended, and a slot in which none ended (nothing arrived: out of range, another
  channel, the other modem gone; :data:`MISS_GRACE_S` of slack) is a missed packet, counted in
  ``pkt_loss_cnt`` and traced (``err``, cause ``missed``) like a packet the model lost.
  :data:`SYNC_LOSSES` undecodable packets in a row, missed or lost, and the modem is out of sync
  (traced on the last one: ``sync: lost``): B stops answering and listens until a good packet from an A,
  A goes on transmitting (it always does); neither counts slots any more until it is in sync again.
  ``wcd``'s link flag is the sync.
- **Channels are bands.** Channel 1–7 is Water Linked's band for it (:data:`CHANNEL_BANDS_KHZ`, from
  its channel table); ``wcs`` moves the link to that band in the simulation, and bands that do not
  overlap never meet (no arrival, no collision), so pairs on different channels never disturb each other.
- **What the far modem prints.** A good packet from the other role is printed ``wrp,8,<payload>*xx``
  when the model delivers it (its ``rx_delay_s`` is the modem's decoding latency); an all-zero packet is
  the sync packet, counted but never printed (the modem filters it, whoever queued it).
- **``wcd``.** ``pkt_cnt`` counts the packets received from the other role (sync included),
  ``pkt_loss_cnt`` those the model lost at this modem (collision, error model: each traced ``err`` by the
  model with its cause) and the missed ones (above), the link flag says whether the modem is in sync; the
  bit error rate is 0.0 (the model loses packets whole, it draws no bit errors).

Not emulated: the modem's serial line timing (115200 baud: 1.2 ms for a ``wcq``), an A hearing another
A (only the other role's packets are decoded), the modem's own queue bound (not published: hilgate's
is :data:`QUEUE_MAX`, beyond which ``wrq,n``).
"""

from __future__ import annotations

import logging
from typing import Any

from hilgate.core.backend import AppFrame, PhyEvent
from hilgate.core.endpoint import TAKEN, LinkPort
from hilgate.core.packets import BROADCAST, Raw

from .emulators import EmulatedModem
from .m64_codec import BadChecksum, Command, Malformed, ModemCodec

log = logging.getLogger(__name__)

PAYLOAD = 8
VERSION = ("1", "0", "1")  # the protocol version the public document describes (wrv,1,0,1)
SLOT_S = 1.0         # role A's transmit period: "about one packet a second each way"
TURNAROUND_S = 0.05  # role B's answer starts this long after A's packet has ended (hilgate's choice)
SYNC_LOSSES = 3      # out of sync after this many undecodable packets in a row ("several": hilgate's figure)
MISS_GRACE_S = 0.5   # a packet is missed when none ended within a slot and this much after the last one
QUEUE_MAX = 1024     # packets the emulated modem queues (the real bound is not published)
SYNC = bytes(PAYLOAD)
CHANNEL_BANDS_KHZ = {1: (31.25, 62.25), 2: (62.25, 93.75), 3: (93.75, 125.0), 4: (125.0, 156.0),
                     5: (156.0, 187.0), 6: (187.0, 218.0), 7: (218.0, 250.0)}
"""Water Linked's channel table (its public documentation, "Channel overview"): the band of each
modem channel; neighbouring bands only touch, so they do not overlap."""


class M64Emulator(EmulatedModem):
    """A Water Linked Modem-M64 (the module's docstring)."""

    busy = False
    codec = ModemCodec

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        super().__init__(port, spec, scheduler)
        self.role = str(spec.get("role", "a"))
        self.channel = int(spec.get("channel", 1))
        self.queue: list[bytes] = []
        self.received = 0      # wcd pkt_cnt
        self.lost_packets = 0  # wcd pkt_loss_cnt
        self.in_sync = False   # heard the other role lately (B answers A only then)
        self.losses_in_row = 0
        self.answer_timer = None
        self.slot_timer = None
        self.miss_timer = None  # while in sync: when the next packet from the other role is missed
        self.started = scheduler.now()
        self._tune()
        self._schedule_slot()
        self._serve_hosts()

    def close(self) -> None:
        for timer in (self.slot_timer, self.answer_timer, self.miss_timer):
            self.scheduler.cancel(timer)
        self.slot_timer = self.answer_timer = self.miss_timer = None
        super().close()

    # -- host → modem ----------------------------------------------------------------------------------

    def _on_data(self, host: Any, data: bytes) -> None:
        codec = self._codec_of(host)
        for event in codec.receive_data(data):
            match event:
                case Command():
                    host.write(self._command(event))
                case BadChecksum() | Malformed():
                    host.write(codec.refusal(event))

    def _command(self, command: Command) -> bytes:
        handler = self.COMMANDS.get(command.letter)
        if handler is None:
            return ModemCodec.refusal(command)
        answer = handler(self, command)
        if answer is None:
            return ModemCodec.refusal(command)
        return ModemCodec.response(command.letter, *answer)

    def _version(self, command: Command) -> tuple[str, ...] | None:
        return VERSION if not command.options else None

    def _payload_size(self, command: Command) -> tuple[str, ...] | None:
        return (str(PAYLOAD),) if not command.options else None

    def _get_settings(self, command: Command) -> tuple[str, ...] | None:
        return (self.role, str(self.channel)) if not command.options else None

    def _set_settings(self, command: Command) -> tuple[str, ...] | None:
        if len(command.options) != 2:
            return None
        role, channel = command.options
        if role not in ("a", "b") or not channel.isdigit() or int(channel) not in CHANNEL_BANDS_KHZ:
            return ("n",)
        changed = (role, int(channel)) != (self.role, self.channel)
        self.role, self.channel = role, int(channel)
        if changed:  # a new pairing: the link starts again
            self.in_sync = False
            self.losses_in_row = 0
            for timer in (self.answer_timer, self.miss_timer):
                self.scheduler.cancel(timer)
            self.answer_timer = self.miss_timer = None
            self._tune()
            self._schedule_slot()
        return ("a",)

    def _queue_length(self, command: Command) -> tuple[str, ...] | None:
        return (str(len(self.queue)),) if not command.options else None

    def _flush(self, command: Command) -> tuple[str, ...] | None:
        if command.options:
            return None
        for payload in self.queue:
            self.port.lost("flushed", len(payload), src="app")
        self.queue.clear()
        return ("a",)

    def _diagnostic(self, command: Command) -> tuple[str, ...] | None:
        if command.options:
            return None
        return ("y" if self.in_sync else "n", str(self.received), str(self.lost_packets), "0.0")

    def _queue_packet(self, command: Command) -> tuple[str, ...] | None:
        payload = command.payload
        if payload is None:
            return None
        if len(payload) != PAYLOAD or command.options != (str(PAYLOAD),):
            return ("n",)
        if len(self.queue) >= QUEUE_MAX:
            self.port.lost("queue_full", len(payload), src="app")
            return ("n",)
        self.queue.append(payload)
        return ("a",)

    COMMANDS = {"v": _version, "n": _payload_size, "c": _get_settings, "s": _set_settings, "l": _queue_length,
                "f": _flush, "d": _diagnostic, "q": _queue_packet}

    # -- the slots -------------------------------------------------------------------------------------

    def _tune(self) -> None:
        self.port.set_band(CHANNEL_BANDS_KHZ[self.channel])

    def _schedule_slot(self) -> None:
        """Role A transmits at power-on + k · SLOT_S; role B only answers."""
        self.scheduler.cancel(self.slot_timer)
        self.slot_timer = None
        if self.role == "a":
            now = self.scheduler.now()
            k = int((now - self.started) // SLOT_S) + 1
            self.slot_timer = self.scheduler.at(self.started + k * SLOT_S, self._slot)

    def _slot(self) -> None:
        self.slot_timer = self.scheduler.at(self.scheduler.now() + SLOT_S, self._slot)
        self._transmit()

    def _transmit(self) -> None:
        payload = self.queue.pop(0) if self.queue else SYNC
        frame = AppFrame(payload, payload, Raw(), 0, self.port.address, BROADCAST, self.scheduler.now())
        frame.meta = {"m64": "sync" if payload == SYNC else "data", "role": self.role, "channel": self.channel}
        self.port.send(frame)

    def _answer(self) -> None:
        self.answer_timer = None
        if self.role == "b" and self.in_sync:
            self._transmit()

    def _from_partner(self, frame: AppFrame | None) -> bool:
        meta = (frame.meta if frame is not None else None) or {}
        return "m64" in meta and meta.get("role") != self.role and meta.get("channel") == self.channel

    # -- what the simulated PHY does --------------------------------------------------------------------

    def phy(self, event: PhyEvent) -> None:
        """Arrivals from the other role: their end times B's answer and the next expected packet, their
        losses count in ``wcd``."""
        if event.kind != "rx_end" or not self._from_partner(event.frame):
            return
        self.scheduler.cancel(self.miss_timer)
        self.miss_timer = None
        if event.cause is not None:
            self.lost_packets += 1
            self._undecodable()
        else:
            self.losses_in_row = 0
            self.in_sync = True
        if self.in_sync:
            self.miss_timer = self.scheduler.at(event.end + SLOT_S + MISS_GRACE_S, self._missed)
        if self.role == "b" and self.in_sync and self.answer_timer is None:
            self.answer_timer = self.scheduler.at(event.end + TURNAROUND_S, self._answer)

    def _missed(self) -> None:
        """No packet from the other role ended in its slot: the modem lost it (the signal is gone)."""
        self.miss_timer = None
        self.lost_packets += 1
        in_sync = self._undecodable()
        self.port.lost("missed", PAYLOAD, ev="err", role=self.role, channel=self.channel,
                       **({} if in_sync else {"sync": "lost"}))
        if in_sync:
            self.miss_timer = self.scheduler.at(self.scheduler.now() + SLOT_S, self._missed)

    def _undecodable(self) -> bool:
        """One more packet in a row that could not be decoded; whether the modem is still in sync."""
        self.losses_in_row += 1
        if self.losses_in_row >= SYNC_LOSSES:
            self.in_sync = False  # B back to listen mode; A keeps transmitting, as it always does
        return self.in_sync

    # -- medium → host -----------------------------------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        if not self._from_partner(frame):
            return TAKEN  # not a packet this modem decodes (another A, another modem's traffic)
        self.received += 1
        payload = frame.payload
        if payload == SYNC or len(payload) != PAYLOAD:
            return TAKEN  # the sync packet: filtered out by the receiving modem
        self._to_hosts(ModemCodec.packet(payload))
        return TAKEN

    def state(self, ready: bool) -> None:
        pass
