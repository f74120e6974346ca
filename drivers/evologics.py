"""``backend: evologics``: a real EvoLogics S2C modem behind a link id, over serial or TCP.

The driver keeps the modem in command mode and sends GLI frames as instant messages
(``AT*SENDIM``, at most 64 bytes, with or without acoustic acknowledgement) or as burst data
(``AT*SEND``, at most 1024 bytes; both from the link's ``limits:``, and a larger frame is refused when
the application sends it).  Received ``RECVIM``, ``RECVIMS``, ``RECVPBM`` and ``RECV`` go to
the applications.  Only one command is ever in flight, each with a timeout; an IM with ``ack`` holds
the next one back until ``DELIVEREDIM`` or ``FAILEDIM`` (the modem would answer ``BUSY DELIVERING``).
After a delivery the driver asks ``AT?T`` for the one-way propagation time and traces it with the
range it implies.  Recovery follows the field drivers: ``ERROR BUFFER FULL`` (and buffers-not-empty)
→ ``ATZ4`` then retry; ``ERROR INTERNAL`` → ``ATZ4`` and the whole init again; ``BUSY`` → retry in
half a second.  While the port is down, up to ``queue_frames`` frames wait; beyond that they are
dropped, counted and traced.
"""

from __future__ import annotations

import logging
from collections import deque
from typing import Any, Callable

from hilgate.core.backend import AppFrame
from hilgate.core.packets import PacketClass, PacketError, Raw

from .evologics_codec import AsyncError, AtProtocolError, Data, HostCodec, Notification, Reply, Unexpected
from .modem_backend import ModemBackend
from .table import EVOLOGICS_LIMITS, EvologicsOptions  # declared in the backend table, with its scene checks

log = logging.getLogger(__name__)

SOUND_SPEED = 1500.0


class EvologicsBackend(ModemBackend):
    kind = "evologics"

    def __init__(self, link_id: str, address: int, packet: PacketClass, options: EvologicsOptions, scheduler: Any,
                 trace: Callable[[dict], Any]):
        super().__init__(link_id, address, packet, options, scheduler, trace)
        self.limits = options.limits or EVOLOGICS_LIMITS
        self.codec = HostCodec(eol=options.eol_bytes())
        self.commands: deque[tuple[str, str, bytes | None, tuple, Callable[[Reply], Any] | None]] = deque()
        self.inflight: tuple | None = None
        self.inflight_timer = None
        self.sending: AppFrame | None = None
        self.delivery_timer = None
        self.retry_timer = None
        self._open_port()

    # -- Backend ---------------------------------------------------------------------------------

    @property
    def idle(self) -> bool:
        return not self.queue and self.sending is None

    def admit(self, frame: AppFrame) -> None:
        """A frame larger than the mode takes (``im:``, the link's ``limits:``) is refused now, with the
        text a simulated link with the same limits gives (:meth:`ModemLimits.refusal`)."""
        self.limits.admit(len(frame.real), "im" if self.options.im else "burst")

    def close(self) -> None:
        for timer in (self.inflight_timer, self.delivery_timer, self.retry_timer):
            self.scheduler.cancel(timer)
        super().close()

    # -- the port and the init sequence ---------------------------------------------------------------

    def _on_port(self, up: bool, reason: str | None) -> None:
        self.codec = HostCodec(eol=self.options.eol_bytes())
        self.commands.clear()
        self.inflight = None
        for timer in (self.inflight_timer, self.delivery_timer, self.retry_timer):
            self.scheduler.cancel(timer)
        if self.sending is not None:  # an IM was under way: send it again after reconnecting
            self.queue.appendleft(self.sending)
            self.sending = None
        if up:
            self.set_state("starting")
            self._init()
        else:
            self.set_state("down", reason)

    def _init(self) -> None:
        o = self.options
        steps = [("", "")]  # a bare AT: is anyone there?
        steps.append(("!AL", str(self.address)))
        if o.source_level is not None:
            steps.append(("!L", str(o.source_level)))
        if o.gain is not None:
            steps.append(("!G", str(o.gain)))
        if o.extended:
            steps.append(("@ZX", "1"))
        if o.im_retries is not None:
            steps.append(("!RI", str(o.im_retries)))
        for name, args in steps[:-1]:
            self.command(name, args, on_reply=self._init_reply)
        self.command(*steps[-1], on_reply=self._init_done)

    def _init_reply(self, reply: Reply) -> None:
        if not reply.ok:
            log.warning("%s: AT%s answered %s", self.link_id, reply.command, reply.text)

    def _init_done(self, reply: Reply) -> None:
        self._init_reply(reply)
        self.set_state("up")
        self.pump()

    # -- commands -----------------------------------------------------------------------------------

    def command(self, name: str, args: str = "", payload: bytes | None = None, fields: tuple = (),
                on_reply: Callable[[Reply], Any] | None = None) -> None:
        self.commands.append((name, args, payload, fields, on_reply))
        self._next_command()

    def _next_command(self) -> None:
        if self.inflight is not None or not self.commands or not self.port.up:
            return
        self.inflight = self.commands.popleft()
        name, args, payload, fields, _ = self.inflight
        self.port.write(self.codec.command(name, args, payload, fields))
        self.inflight_timer = self.scheduler.after_wall(self.options.command_timeout_s, self._command_timeout)

    def _command_timeout(self) -> None:
        if self.inflight is None:
            return
        name = self.inflight[0]
        log.warning("%s: no answer to AT%s", self.link_id, name)
        self.codec.timeout()
        self._finish_command(Reply(name, "TIMEOUT"))

    def _finish_command(self, reply: Reply) -> None:
        self.scheduler.cancel(self.inflight_timer)
        callback = self.inflight[4] if self.inflight else None
        self.inflight = None
        if callback is not None:
            callback(reply)
        self._next_command()

    # -- frames out -----------------------------------------------------------------------------------

    def pump(self) -> None:
        if self._state != "up" or self.sending is not None or not self.queue or self.retry_timer:
            return
        frame = self.sending = self.queue.popleft()
        if self.options.im:
            fields = (frame.dst, "ack" if self.options.ack else "noack")
            self.command("*SENDIM", payload=frame.real, fields=fields, on_reply=self._sent)
        else:
            self.command("*SEND", payload=frame.real, fields=(frame.dst,), on_reply=self._sent)

    def _sent(self, reply: Reply) -> None:
        frame = self.sending
        if frame is None:
            return
        now = round(self.scheduler.now(), 9)
        if reply.ok:
            self.tx_packets += 1
            self.trace({"t": now, "ev": "tx", "link": self.link_id, "dst": frame.dst, "size": len(frame.real)})
            if self.options.im and self.options.ack and frame.dst != 255:
                self.delivery_timer = self.scheduler.after_wall(self.options.delivery_timeout_s,
                                                                self._delivery_timeout)
                return
            self._frame_done()
            return
        error = reply.text
        if "BUFFER" in error:  # BUFFER FULL / BUFFERS NOT EMPTY: clear the transmit buffer, try again
            self.command("Z", "4")
            self._retry_later(frame, 1.0, error)
        elif "INTERNAL" in error:
            self.command("Z", "4")
            self.set_state("starting")
            self._init()
            self._retry_later(frame, 1.0, error)
        elif error.startswith("BUSY") or error == "TIMEOUT":
            self._retry_later(frame, 0.5, error)
        else:  # WRONG FORMAT, OUT OF RANGE…: this frame will never go
            log.warning("%s: modem refused a frame: %s", self.link_id, error)
            self.sending = None
            self.drop(frame, "refused")
            self._frame_done()

    def _retry_later(self, frame: AppFrame, delay: float, why: str) -> None:
        self.sending = None
        self.queue.appendleft(frame)
        self.event("retry", cause=why)

        def again() -> None:
            self.retry_timer = None
            self.pump()

        self.retry_timer = self.scheduler.after_wall(delay, again)

    def _frame_done(self) -> None:
        self.scheduler.cancel(self.delivery_timer)
        self.delivery_timer = None
        self.sending = None
        if self.idle and self.on_idle is not None:
            self.on_idle()
        self.pump()

    def _delivery_timeout(self) -> None:
        frame = self.sending
        if frame is not None:
            self.drop(frame, "no_report")
        self._frame_done()

    # -- bytes in -------------------------------------------------------------------------------------

    def _on_data(self, data: bytes) -> None:
        for event in self.codec.receive_data(data):
            match event:
                case Reply():
                    if self.inflight is not None:
                        self._finish_command(event)
                case Notification():
                    self._notification(event)
                case AsyncError(reason=reason):
                    self.trace({"t": round(self.scheduler.now(), 9), "ev": "modem_error", "link": self.link_id,
                                "cause": reason})
                case Unexpected() | AtProtocolError():
                    log.info("%s: unexpected from the modem: %s", self.link_id, event)
                case Data():
                    log.info("%s: %d bytes of burst data from the modem, ignored", self.link_id, len(event.payload))

    def _notification(self, n: Notification) -> None:
        now = round(self.scheduler.now(), 9)
        if n.name in ("RECVIM", "RECVIMS", "RECVPBM", "RECV") and n.payload is not None:
            self._received(n, now)
        elif n.name in ("DELIVEREDIM", "FAILEDIM"):
            delivered = n.name == "DELIVEREDIM"
            self.trace({"t": now, "ev": "delivered" if delivered else "failed", "link": self.link_id,
                        "dst": int(n.field(0) or 0)})
            if self.sending is not None and self.delivery_timer is not None:
                if not delivered:
                    self.drop(self.sending, "failed")
                self._frame_done()
            if delivered:
                self.command("?T", on_reply=self._propagation_time)

    def _propagation_time(self, reply: Reply) -> None:
        if reply.text.strip().isdigit():
            microseconds = int(reply.text.strip())
            self.trace({"t": round(self.scheduler.now(), 9), "ev": "ptime", "link": self.link_id,
                        "ptime_us": microseconds, "range_m": round(microseconds * SOUND_SPEED / 1e6, 2)})

    def _received(self, n: Notification, now: float) -> None:
        src = int(n.field(1) or 0)
        dst = int(n.field(2) or 0)
        extra: dict[str, Any] = {}
        if n.name in ("RECVIM", "RECVIMS", "RECVPBM") and len(n.fields) >= 7:
            extra = {"rssi": _int(n.fields[-3]), "integrity": _int(n.fields[-2])}
        elif n.name == "RECV" and len(n.fields) >= 8:
            extra = {"rssi": _int(n.fields[4]), "integrity": _int(n.fields[5]), "ptime_us": _int(n.fields[6])}
        real = n.payload
        try:
            if isinstance(self.packet, Raw):
                payload = real
            else:
                real, payload, _, _ = self.packet.parse_real(real)
        except PacketError as exc:
            self.drops += 1
            self.trace({"t": now, "ev": "err", "link": self.link_id, "src": src, "size": len(n.payload),
                        "cause": exc.reason, **extra})
            return
        self.rx_packets += 1
        self.trace({"t": now, "ev": "rx", "link": self.link_id, "src": src, "dst": dst, "size": len(real),
                    "kind": n.name.lower(), **extra})
        if self.on_receive is not None:
            self.on_receive(AppFrame(real, payload, self.packet, 0, src, dst, self.scheduler.now()))


def _int(text: str) -> int | None:
    try:
        return int(float(text))
    except ValueError:
        return None
