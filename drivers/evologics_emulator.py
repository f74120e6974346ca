"""A simulated modem that looks real: an EvoLogics S2C on a pseudo-terminal or TCP.

``emulate: {protocol: evologics, pty: /tmp/evo0}`` on a ``backend: sim`` link creates a pty whose
slave is linked at that path (or ``tcp: 9200``, a loopback listener), and answers there like the
modem would, with the link's simulated modem behind it.  Software written for the real modem runs
unchanged against the simulation: ``AT*SENDIM,5,2,ack,hello`` gets ``OK``; the other vehicle's
emulated modem prints ``RECVIM,5,1,2,ack,…`` when the model delivers the frame, with the RSSI,
integrity and radial velocity of :mod:`hilgate.models.link_budget`; its modem answers with an ACK frame
on the channel (:mod:`hilgate.models.acoustic_ack`) and the sender prints ``DELIVEREDIM,2`` when that
ACK has reached it, or ``FAILEDIM,2`` once the ``!RI`` retries went unanswered; ``AT?T`` answers the
one-way time measured from that round trip.  A link with ``usbl:`` prints ``USBLLONG`` and
``USBLANGLES`` (after ``AT@ZU1``) from the simulated geometry after each exchange; settings answer as
a modem does.  Like a modem just powered on, it starts in command mode (``ATO`` enters data mode,
``+++AT`` escapes work there). Enough of the S2C's command surface is there for field
drivers that poll and check it (LSTS DUNE's task: ``AT?MODE``, ``ATI1``, ``AT?CLOCK``, ``AT?P``,
``SENDEND``, burst reports); the conformance table of docs/conformance.md lists what is and is not emulated.
"""

from __future__ import annotations

from typing import Any

from hilgate.core.backend import AppFrame, PhyEvent
from hilgate.core.endpoint import TAKEN, LinkPort
from hilgate.core.packets import BROADCAST, Raw

from .emulated_modem import EmulatedModem
from .evologics_codec import BadCommand, Command, Data, ModemCodec
from .evologics_commands import EvologicsCommands
from .evologics_settings import Firmware, Settings
from .table import ModemLimits, limits_for

FOREVER = 1 << 30  # !RI255: retry for ever


class EvologicsEmulator(EvologicsCommands, EmulatedModem):
    """An EvoLogics S2C modem in front of a simulated link.

    Its settings (:mod:`.evologics_settings`) are range-checked and kept as running, stored and factory
    values; ``AT!AL`` moves the link to the new address in the simulation.  Its transmit pool holds what
    it accepted until the model's transmission of it ends (``ERROR BUFFER FULL`` beyond ``ZL`` bytes;
    ``ATZ1``/``ATZ3``/``ATZ4`` empty it).  With ``AT@ZX1`` it reports what the simulated PHY does
    (SENDSTART/SENDEND, RECVSTART/RECVEND/RECVFAILED, BITRATE, SRCLEVEL) at the model's times."""

    codec = ModemCodec

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        super().__init__(port, spec, scheduler)
        self.firmware = Firmware.from_options(spec.get("firmware"))
        self.settings = Settings(port.address)
        self.pending_ack: AppFrame | None = None
        self.bursts: dict[int, AppFrame] = {}  # packet counter → burst awaiting its report
        self.packet_counter = 0
        self.pool: dict[int, AppFrame] = {}  # id → accepted frames whose transmission has not ended
        self.receiving: dict[int, float] = {}  # id of a frame arriving → when its arrival began
        self.dropped = 0     # AT?ZD: frames the modem dropped (buffer cleared, no remote address)
        self.overflows = 0   # AT?ZO: frames refused because the transmit pool was full
        self.clock_offset = 0.0  # AT!UT
        self.last_ptime_us = 0
        self.last_rssi = -50
        self.last_integrity = 150
        self.last_velocity = 0.0
        self.received = False  # AT?P answers zeros until something was received
        self._serve_hosts()

    @property
    def limits(self) -> ModemLimits:
        """What this modem accepts: the link's ``limits:`` (read anew, a reload may change them)."""
        return limits_for("evologics", self.port.limits)

    # -- host → modem -------------------------------------------------------------------------------

    def _on_data(self, host: Any, data: bytes) -> None:
        codec = self._codec_of(host)
        for event in codec.receive_data(data):
            match event:
                case Command():
                    self._command(host, codec, event)
                case BadCommand(reason=reason):
                    host.write(codec.error(None, reason))
                case Data(payload=payload):
                    self._raw_data(payload)

    def _raw_data(self, payload: bytes) -> None:
        """Burst data in data mode goes to ``AR``; with ``AR`` 0 a modem cannot send it (dropped, counted
        in ``AT?ZD`` and traced), nor beyond the transmit pool (``AT?ZO``)."""
        remote = self.settings["AR"]
        most = self.limits.most("burst") or len(payload) or 1
        for start in range(0, len(payload), most):
            piece = payload[start:start + most]
            if remote == 0:
                self.dropped += 1
                self.port.lost("no_remote_address", len(piece), src="app")
            elif self._pooled() + len(piece) > self.settings["ZL"]:
                self.overflows += 1
                self.port.lost("buffer_full", len(piece), src="app")
            else:
                self._send(piece, remote, "burst", True)

    def _send(self, payload: bytes, dst: int, kind: str, ack: bool) -> None:
        frame = AppFrame(payload, payload, Raw(), 0, self.port.address, dst, self.scheduler.now())
        frame.meta = {"kind": kind, "ack": ack}
        if kind == "burst":  # AT?PC numbers it
            self.packet_counter += 1
            frame.meta["pc"] = self.packet_counter
        if dst != BROADCAST and (ack or kind == "burst"):
            # the receiving modem answers on the channel (hilgate.models.acoustic_ack); an IM retries !RI
            # times (255: for ever), a burst !RC times (a burst is acknowledged whatever ``ack`` says);
            # the model's outcome is the report
            if kind == "burst":
                frame.ack_retries = int(self.settings["RC"])
            else:
                retries = int(self.settings["RI"])
                frame.ack_retries = FOREVER if retries == 255 else retries
            frame.on_acknowledged = self._acknowledged
            if kind == "burst":
                self.bursts[frame.meta["pc"]] = frame
            else:
                self.pending_ack = frame
        self.pool[id(frame)] = frame
        self.port.send(frame)

    # -- delivery reports -------------------------------------------------------------------------------

    def _awaited(self, frame: AppFrame) -> bool:
        if frame is self.pending_ack:
            return True
        pc = (frame.meta or {}).get("pc")
        return pc is not None and self.bursts.get(pc) is frame

    def _acknowledged(self, frame: AppFrame, delivered: bool, tau: float | None) -> None:
        """The model's report on an ``ack`` IM or a burst: its ACK came back (``tau``: the one-way time
        the modem measured from the round trip), or the last retry went unanswered."""
        if not self._awaited(frame):
            return  # (cleared by ATZ meanwhile: no report, as on a modem)
        if frame is self.pending_ack:
            self.pending_ack = None
        else:
            del self.bursts[frame.meta["pc"]]
        if delivered and tau is not None:
            self.last_ptime_us = round(tau * 1e6)
        self._notify(self._delivery_line(frame, delivered))
        if delivered:
            self._usbl(frame.dst, self.scheduler.now(), tau)
        self.port.state_changed()

    @staticmethod
    def _delivery_line(frame: AppFrame, delivered: bool) -> str:
        """The one place a delivery decision becomes a report: ``DELIVEREDIM,<dst>``/``FAILEDIM,<dst>``
        for an instant message, ``DELIVERED,<pc>,<dst>``/``FAILED,<pc>,<dst>`` for a burst."""
        if (frame.meta or {}).get("kind") == "burst":
            return f"{'DELIVERED' if delivered else 'FAILED'},{frame.meta['pc']},{frame.dst}"
        return f"{'DELIVEREDIM' if delivered else 'FAILEDIM'},{frame.dst}"

    def _notify(self, text: str, payload: bytes | None = None) -> None:
        for host, codec in list(self.codecs.items()):
            host.write(codec.notify_line(text, payload))

    def _extended(self, text: str) -> None:
        """An extended notification, printed only after ``AT@ZX1``."""
        if self.settings["ZX"]:
            self._notify(text)

    # -- what the simulated PHY does (extended notifications, the transmit pool) ----------------------

    def phy(self, event: PhyEvent) -> None:
        frame = event.frame
        if frame is None:
            return  # background traffic and MAC frames: nothing a host of this modem sent or will read
        if event.kind == "tx":
            if id(frame) not in self.pool:
                return
            kind = frame.meta["kind"]
            duration_us = round((event.end - event.start) * 1e6)
            if kind == "burst":
                self._extended(f"BITRATE,local,{self._bitrate()}")
            self._extended(f"SENDSTART,{frame.dst},{kind},{duration_us},{round((event.start - frame.t0) * 1e6)}")
            self.scheduler.at(event.end, self._sent, frame, duration_us)
            return
        if event.dst != self.port.address and event.dst != BROADCAST:
            return
        if event.kind == "rx_start":
            self.receiving[id(frame)] = event.start
            self._extended("RECVSTART")
            return
        start = self.receiving.pop(id(frame), None)
        duration_us = round((event.end - start) * 1e6) if start is not None else 0
        rssi, integrity = self._signal(frame.src, event.end)
        if event.cause is None:
            self._extended(f"RECVEND,{round(event.end * 1e6)},{duration_us},{rssi},{integrity}")
        else:
            self._extended(f"RECVFAILED,0.00,{rssi},0")

    def _sent(self, frame: AppFrame, duration_us: int) -> None:
        """The model's transmission of ``frame`` ended: it leaves the pool; ``SENDEND`` (a host waits for
        it to free the modem after a ``noack`` message)."""
        if self.pool.pop(id(frame), None) is not None:
            now = self.scheduler.now()
            self._extended(f"SENDEND,{frame.dst},{frame.meta['kind']},{round(now * 1e6)},{duration_us}")

    def _signal(self, src: int, t: float) -> tuple[int, int]:
        """RSSI (dB) and integrity of a frame from ``src`` heard at ``t`` (hilgate.models.link_budget)."""
        heard = self.port.measure.reception_from(src, t)
        if heard is None:  # a sender the model does not know (or out of range): nothing measured
            return self.last_rssi, 0
        return heard.rssi_db, heard.integrity

    # -- medium → host ----------------------------------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        meta = frame.meta or {}
        kind = meta.get("kind", "im")
        payload = frame.real
        heard = self.port.measure.reception_from(frame.src, t)
        d = heard.distance_m if heard is not None else 0.0
        if heard is not None:  # the model's measurements (hilgate.models.link_budget), not constants
            self.last_rssi, self.last_integrity, self.last_velocity = heard.rssi_db, heard.integrity, heard.velocity_mps
        velocity = self.last_velocity
        airtime = self.port.measure.airtime(len(frame.real)) or 0.0  # the whole frame on air
        duration_us = round(airtime * 1e6)
        ptime_us = round((self.port.measure.delay_from(frame.src, t) or 0.0) * 1e6)  # the channel's: BELLHOP's in water
        self.received = True
        if kind == "burst":
            self._extended(f"BITRATE,remote,{self._bitrate()}")
        for host, codec in list(self.codecs.items()):
            if kind == "burst":
                if codec.data_mode:
                    host.write(payload)
                    continue
                bit_time = self.port.measure.airtime(1)
                bitrate = round(8 / bit_time) if bit_time else 0
                text, body = ModemCodec.recv_burst(frame.src, frame.dst, payload, bitrate,
                                                   self.last_rssi, self.last_integrity, ptime_us, velocity)
            elif kind == "ims":
                text = (f"RECVIMS,{len(payload)},{frame.src},{frame.dst},{round(t * 1e6)},{duration_us},"
                        f"{self.last_rssi},{self.last_integrity},{velocity:.2f},")
                body = payload
            elif kind == "pbm":
                text = (f"RECVPBM,{len(payload)},{frame.src},{frame.dst},{duration_us},{self.last_rssi},"
                        f"{self.last_integrity},{velocity:.2f},")
                body = payload
            else:
                text, body = ModemCodec.recvim(frame.src, frame.dst, payload, bool(meta.get("ack")), duration_us,
                                               self.last_rssi, self.last_integrity, velocity)
            host.write(codec.notify_line(text, body))
        self._usbl(frame.src, t, ptime_us / 1e6, t - airtime)
        return TAKEN

    def _usbl(self, address: int, t: float, tau: float | None, measured: float | None = None) -> None:
        """After an exchange with ``address``: a USBL link with ``AT@ZU1`` prints its fix of that modem."""
        if not self.settings["ZU"]:
            return
        found = self.port.measure.usbl_fix(address, t)
        if found is None:
            return
        heard, fix = found
        for line in usbl_lines(heard, fix, address, t, t if measured is None else measured,
                               tau if tau is not None else 0.0):
            self._notify(line)

    def state(self, ready: bool) -> None:
        """A modem says nothing when its transmit buffer drains (AT?ZS / BUSY answers say it)."""

    @property
    def busy(self) -> bool:
        return self.pending_ack is not None


def usbl_lines(heard: Any, f: Any, address: int, t: float, measured: float, tau: float) -> list[str]:
    """``USBLLONG`` and ``USBLANGLES`` of a fix ``f`` (``models.usbl.UsblFix``) for a reception ``heard``
    (``models.link_budget.Reception``), in the reference's field order and the precision real modems print
    (times to the µs, metres and radians to 4 decimals)."""
    x, y, z = f.local
    e, n, u = f.enu
    roll, pitch, yaw = f.orientation
    common = f"{t:.6f},{measured:.6f},{address}"
    return [
        f"USBLLONG,{common},{x:.4f},{y:.4f},{z:.4f},{e:.4f},{n:.4f},{u:.4f},{roll:.4f},{pitch:.4f},{yaw:.4f},"
        f"{round(tau * 1e6)},{heard.rssi_db},{heard.integrity},{f.accuracy_m:.4f}",
        f"USBLANGLES,{common},{f.local_bearing:.4f},{f.local_elevation:.4f},{f.bearing:.4f},{f.elevation:.4f},"
        f"{roll:.4f},{pitch:.4f},{yaw:.4f},{heard.rssi_db},{heard.integrity},{f.accuracy_m:.4f}",
    ]


