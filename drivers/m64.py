"""``backend: m64``: a real Water Linked Modem-M64 behind a link id, on a serial port.

At start (and after every reconnection) the driver does what ``wlmodem``'s ``connect`` and
``cmd_configure`` do: an empty line, ``wcv`` (protocol major version 1), ``wcn`` (the payload size, 8
on the M64), ``wcs,<role>,<channel>``; then ``wcf``, so that what the modem still queues of a frame cut
short by the reconnection does not go (the frame goes again whole, after a frame end).  A GLI frame then goes out as a ``WlUDPSocket`` datagram: the
frame's bytes on air, CRC-8, COBS/R, a zero byte, cut into packets of the payload size
(:mod:`.m64_codec`), so a ``wlmodem`` datagram application on the far modem reads it, and a datagram
it sends arrives here as a frame.  Like ``WlUDPSocket`` the driver keeps ``queued_packets`` packets in
the modem's queue, asking its length (``wcl``) every ``poll_s``; the modem sends one a second.

Received packets (``wrp``) are joined into datagrams; one that fails its CRC (a packet of it was lost
on the way) is dropped, counted and traced (``err``, cause ``crc``).  Every ``diagnostic_s`` the
modem's own figures (``wcd``: link, packets received, packets lost, bit error rate) go into the trace
(``ev: modem_stats``).  One command is in flight at a time, each with a timeout; ``wr?``/``wr!`` fail
it.  The M64 carries no addresses: a frame's source and destination are those of its packet class,
else the pair's other end and broadcast.  While the port is down, up to ``queue_frames`` frames wait.
"""

from __future__ import annotations

import logging
from collections import deque
from typing import Any, Callable

from hilgate.core.backend import AppFrame
from hilgate.core.packets import BROADCAST, PacketClass, PacketError, Raw

from .m64_codec import (BadChecksum, BadDatagram, Datagram, Deframer, HostCodec, Malformed, Packet, Refused,
                        Response, frame, packets)
from .modem_backend import ModemBackend
from .table import M64_LIMITS, M64Options  # declared in the backend table, with its scene checks

log = logging.getLogger(__name__)

Reply = Callable[[Response | None], Any]


class M64Backend(ModemBackend):
    kind = "m64"

    def __init__(self, link_id: str, address: int, packet: PacketClass, options: M64Options, scheduler: Any,
                 trace: Callable[[dict], Any]):
        super().__init__(link_id, address, packet, options, scheduler, trace)
        self.codec = HostCodec()
        self.deframer = Deframer()
        self.payload_size = 8
        self.commands: deque[tuple[str, tuple[str, ...], bytes | None, Reply]] = deque()
        self.inflight: tuple[str, tuple[str, ...], bytes | None, Reply] | None = None
        self.inflight_timer = None
        self.poll_timer = None
        self.diagnostic_timer = None
        self.restart_timer = None
        self.outgoing: deque[bytes] = deque()  # packets of the frames being sent, not yet in the modem
        self.sending: AppFrame | None = None   # the frame whose packets those are
        self.modem_queue = 0
        self.fresh = True  # the next datagram is the first since a (re)start: it begins with a frame end
        self._open_port()

    @property
    def idle(self) -> bool:
        return not self.queue and self.sending is None and not self.outgoing

    def admit(self, frame: AppFrame) -> None:
        """A frame larger than a datagram of the link's limits is refused when the application sends it."""
        (self.options.limits or M64_LIMITS).admit(len(frame.real), "datagram")

    def send(self, frame: AppFrame) -> bool:
        self.admit(frame)
        return super().send(frame)

    def close(self) -> None:
        self._cancel_timers()
        super().close()

    def _cancel_timers(self) -> None:
        for timer in (self.inflight_timer, self.poll_timer, self.diagnostic_timer, self.restart_timer):
            self.scheduler.cancel(timer)
        self.inflight_timer = self.poll_timer = self.diagnostic_timer = self.restart_timer = None

    # -- the port and the start-up -------------------------------------------------------------------

    def _on_port(self, up: bool, reason: str | None) -> None:
        self.codec = HostCodec()
        self.deframer = Deframer()
        self.commands.clear()
        self.inflight = None
        self._cancel_timers()
        if self.sending is not None:  # its packets were half in the modem: send the whole frame again
            self.queue.appendleft(self.sending)
            self.sending = None
        self.outgoing.clear()
        if up:
            self.set_state("starting")
            self._start()
        else:
            self.set_state("down", reason)

    def _start(self) -> None:
        self.port.write(b"\n")  # as wlmodem: whatever half a sentence the modem holds is ended
        self.command("v", on_reply=self._version)

    def _version(self, reply: Response | None) -> None:
        if reply is None or not reply.options or reply.options[0] != "1":
            self._not_an_m64(f"wcv answered {reply.options if reply else 'nothing'} (protocol 1.x expected)")
            return
        self.command("n", on_reply=self._payload)

    def _payload(self, reply: Response | None) -> None:
        size = reply.options[0] if reply is not None and reply.options else ""
        if not size.isdigit() or not 1 <= int(size) <= 255:
            self._not_an_m64(f"wcn answered {size!r} (a payload size expected)")
            return
        self.payload_size = int(size)
        self.command("s", self.options.role, str(self.options.modem_channel), on_reply=self._configured)

    def _configured(self, reply: Response | None) -> None:
        if reply is None or not reply.ack:
            self._not_an_m64(f"wcs,{self.options.role},{self.options.modem_channel} was refused")
            return
        self.command("f", on_reply=self._flushed)

    def _flushed(self, reply: Response | None) -> None:
        """What the modem still queued of a frame half sent before the port went is dropped (the whole
        frame goes again), and the next datagram starts with a frame end: whatever the far side holds of
        that frame ends there, as a damaged datagram, instead of swallowing the new one."""
        self.fresh = True
        self.set_state("up")
        self.poll_timer = self.scheduler.after_wall(0.0, self._poll)
        if self.options.diagnostic_s > 0:
            self.diagnostic_timer = self.scheduler.after_wall(self.options.diagnostic_s, self._diagnose)
        self.pump()

    def _not_an_m64(self, why: str) -> None:
        """The start-up failed: say why, and try it again in a few seconds (a modem still booting)."""
        log.warning("%s: %s; trying again", self.link_id, why)
        self.set_state("starting", why)
        self.scheduler.cancel(self.restart_timer)
        self.restart_timer = self.scheduler.after_wall(2.0, self._restart)

    def _restart(self) -> None:
        self.restart_timer = None
        if self.port.up:
            self._start()

    # -- commands ------------------------------------------------------------------------------------

    def command(self, letter: str, *options: str, payload: bytes | None = None, on_reply: Reply) -> None:
        self.commands.append((letter, options, payload, on_reply))
        self._next_command()

    def _next_command(self) -> None:
        if self.inflight is not None or not self.commands or not self.port.up:
            return
        self.inflight = self.commands.popleft()
        letter, options, payload, _ = self.inflight
        self.port.write(self.codec.queue(payload) if payload is not None else self.codec.command(letter, *options))
        self.inflight_timer = self.scheduler.after_wall(self.options.command_timeout_s, self._timeout)

    def _timeout(self) -> None:
        if self.inflight is not None:
            log.warning("%s: no answer to wc%s", self.link_id, self.inflight[0])
            self._finish(None)

    def _finish(self, reply: Response | None) -> None:
        self.scheduler.cancel(self.inflight_timer)
        self.inflight_timer = None
        callback = self.inflight[3] if self.inflight is not None else None
        self.inflight = None
        if callback is not None:
            callback(reply)
        self._next_command()

    # -- frames out: keep the modem's queue at queued_packets ----------------------------------------

    def pump(self) -> None:
        if self._state != "up" or self.sending is not None or not self.queue:
            return
        self.sending = self.queue.popleft()
        real = self.sending.real if not isinstance(self.packet, Raw) else self.sending.payload
        framed = (b"\x00" if self.fresh else b"") + frame(real)
        self.fresh = False
        self.outgoing.extend(packets(framed, self.payload_size))

    def _poll(self) -> None:
        self.poll_timer = self.scheduler.after_wall(self.options.poll_s, self._poll)
        if (self.outgoing or self.queue) and self.inflight is None and not self.commands:
            self.command("l", on_reply=self._queue_length)

    def _queue_length(self, reply: Response | None) -> None:
        if reply is None or not reply.options or not reply.options[0].isdigit():
            return
        self.modem_queue = int(reply.options[0])
        if self.modem_queue < self.options.queued_packets:
            self.pump()
            if self.outgoing:
                self.command("q", payload=self.outgoing[0], on_reply=self._queued)

    def _queued(self, reply: Response | None) -> None:
        if reply is None or not reply.ack or not self.outgoing:
            return  # refused or no answer: the same packet goes with the next poll
        self.outgoing.popleft()
        if not self.outgoing and self.sending is not None:
            frame_ = self.sending
            self.sending = None
            self.tx_packets += 1
            self.event("tx", dst=frame_.dst, size=len(frame_.real))
            if self.idle and self.on_idle is not None:
                self.on_idle()
            self.pump()

    # -- the modem's figures ---------------------------------------------------------------------------

    def _diagnose(self) -> None:
        self.diagnostic_timer = self.scheduler.after_wall(self.options.diagnostic_s, self._diagnose)
        self.command("d", on_reply=self._diagnostic)

    def _diagnostic(self, reply: Response | None) -> None:
        if reply is None or len(reply.options) < 4:
            return
        link, received, lost, ber = reply.options[:4]
        if not (received.isdigit() and lost.isdigit()):
            return
        self.event("modem_stats", link_up=link == "y", pkt_cnt=int(received), pkt_loss_cnt=int(lost), ber=ber)

    # -- bytes in --------------------------------------------------------------------------------------

    def _on_data(self, data: bytes) -> None:
        for event in self.codec.receive_data(data):
            match event:
                case Packet(payload=payload):
                    self._packet(payload)
                case Response():
                    if self.inflight is not None and self.inflight[0] == event.letter:
                        self._finish(event)
                    else:
                        log.info("%s: unexpected answer from the modem: %s", self.link_id, event)
                case Refused(reason=reason):
                    if self.inflight is not None:
                        log.warning("%s: the modem refused wc%s (%s)", self.link_id, self.inflight[0], reason)
                        self._finish(None)
                case Malformed() | BadChecksum():
                    log.info("%s: noise from the modem: %s", self.link_id, event)

    def _packet(self, payload: bytes) -> None:
        if len(payload) != self.payload_size:
            self.drops += 1
            self.event("err", size=len(payload), cause="size")
            return
        for event in self.deframer.receive_packet(payload):
            if isinstance(event, Datagram):
                self._received(event.data)
            elif isinstance(event, BadDatagram):
                self.drops += 1
                self.event("err", size=event.size, cause=event.reason)

    def _received(self, data: bytes) -> None:
        try:
            if isinstance(self.packet, Raw):
                real, payload, src, dst = data, data, None, None
            else:
                real, payload, src, dst = self.packet.parse_real(data)
        except PacketError as exc:
            self.drops += 1
            self.event("err", size=len(data), cause=exc.reason)
            return
        src = BROADCAST if src is None else src
        dst = BROADCAST if dst is None else dst
        self.rx_packets += 1
        self.event("rx", src=src, dst=dst, size=len(real))
        if self.on_receive is not None:
            self.on_receive(AppFrame(real, payload, self.packet, 0, src, dst, self.scheduler.now()))
