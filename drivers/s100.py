"""``backend: s100``: a real WFS Seatooth S100 RF modem behind a link id, on a serial port.

It writes each frame as dccomms' S100 bridge does: the link's packet bytes and CR LF, whole with
RTS/CTS flow control, else in 45-byte pieces paced at the air bitrate.  It receives by hunting the
packet class's frames in the byte stream (:mod:`hilgate.drivers.s100_codec`).  The S100 carries no
addresses: frames are broadcast on air, and the packet class (DataLinkFrame) or the application
decides who they are for.  The port reconnects by itself (:mod:`hilgate.drivers.port`); frames wait
(at most ``queue_frames``) while it is down.
"""

from __future__ import annotations

import logging
from collections import deque
from typing import Any, Callable

from hilgate.core.backend import AppFrame
from hilgate.core.packets import Decoded, PacketClass, Raw

from .modem_backend import ModemBackend
from .s100_codec import PIECE, FrameHunter, Notice, Skipped, pieces, wire_class
from .table import S100_LIMITS, S100Options  # declared in the backend table, with its scene checks

log = logging.getLogger(__name__)


class S100Backend(ModemBackend):
    kind = "s100"

    def __init__(self, link_id: str, address: int, packet: PacketClass, options: S100Options, scheduler: Any,
                 trace: Callable[[dict], Any]):
        super().__init__(link_id, address, packet, options, scheduler, trace)
        self.wire = wire_class(packet)
        self.piece = (options.limits or S100_LIMITS).piece_bytes or PIECE  # without RTS/CTS (limits:)
        self.hunter = FrameHunter(packet)
        self.pieces: deque[bytes] = deque()
        self.piece_timer = None
        self._open_port(rtscts=options.rtscts)

    @property
    def idle(self) -> bool:
        # (the last piece is still leaving the modem while its pacing runs: not idle yet)
        return not self.queue and not self.pieces and self.piece_timer is None

    def close(self) -> None:
        self.scheduler.cancel(self.piece_timer)
        super().close()

    def _on_port(self, up: bool, reason: str | None) -> None:
        self.hunter = FrameHunter(self.packet)
        self.scheduler.cancel(self.piece_timer)
        self.piece_timer = None
        self.pieces.clear()  # a frame half written is lost with the adapter; the rest wait
        self.set_state("up" if up else "down", reason)
        if up:
            self.pump()

    def pump(self) -> None:
        # a frame sent while the last piece's pacing runs waits for it: written at once, it would land in
        # a modem still holding that piece (pieces are paced at exactly the air bitrate)
        if self._state != "up" or self.pieces or self.piece_timer is not None or not self.queue:
            return
        frame = self.queue.popleft()
        real = frame.real if not isinstance(self.packet, Raw) else self.wire.encode(frame.payload)
        self.pieces.extend(pieces(real, self.options.rtscts, self.piece))
        self.tx_packets += 1
        self.event("tx", size=len(real))
        self._write_piece()

    def _write_piece(self) -> None:
        self.piece_timer = None
        if not self.pieces:
            if self.idle and self.on_idle is not None:
                self.on_idle()
            self.pump()
            return
        piece = self.pieces.popleft()
        if not self.port.write(piece):
            return  # the port went down; _on_port has cleared the pieces
        pace = 0.0 if self.options.rtscts else len(piece) * 8 / self.options.air_bitrate_bps
        self.piece_timer = self.scheduler.after_wall(pace, self._write_piece)

    def _on_data(self, data: bytes) -> None:
        for event in self.hunter.receive_data(data):
            if isinstance(event, Decoded):
                self.rx_packets += 1
                self.event("rx", size=len(event.real))
                if self.on_receive is not None:
                    real = event.payload if isinstance(self.packet, Raw) else event.real
                    self.on_receive(AppFrame(real, event.payload, self.packet, 0, event.src, event.dst,
                                             self.scheduler.now()))
            elif isinstance(event, Skipped) and event.reason == "crc":
                self.drops += 1
                self.event("err", cause="crc")
            elif isinstance(event, Notice):
                log.info("%s: modem notice %r", self.link_id, event.text)
