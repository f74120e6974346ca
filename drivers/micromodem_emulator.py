"""A WHOI Micro-Modem in front of a simulated link, on a pseudo-terminal.

``emulate: {protocol: micromodem, pty: /tmp/ttyMM0}`` answers there in the modem's NMEA sentences
(:mod:`.micromodem_codec`), with the link's simulated modem behind it:

- **Configuration.** ``$CCCFQ,<name>`` → ``$CACFG,<name>,<value>`` (``ALL``: every one); ``$CCCFG`` sets
  and echoes; ``SRC`` is the link's address (setting it moves the link in the simulation, as ``AT!AL``).
- **A data cycle**, finished or failed every time (a host library whose state timers never fire, as
  ``acomms``', would otherwise wait for ever): ``$CCCYC,0,src,dest,rate,ack,n`` → ``$CACYC`` echo →
  ``$CADRQ`` for each frame ← ``$CCTXD`` (echoed ``$CATXD``) → the packet on the channel → ``$CATXF`` when
  the model's transmission ends.  A frame not given within ``DTO`` seconds of the wall clock (the host's
  time, whatever ``--speed``), or too long for the rate, is ``$CAERR,…,DATA_TIMEOUT,<frame>``: the
  frames given so far go, or, at the first, the cycle ends there.
  Rate 0 (FH-FSK) sends its cycle-init minipacket first (``$CATXF`` after it, then the ``$CADRQ``).  A
  packet is one frame of the model with the rate's own air time (:data:`~.micromodem_codec.RATES`), so
  the model loses or keeps it whole.
- **The sender** prints ``$CATXP,<bytes>`` when the model puts the packet on air and ``$CATXF,<bytes>``
  when it is off the air (``TXP``/``TXF`` 0: not).
- **The receiver** prints ``$CARXP,<0 FSK|1 PSK>`` when a packet begins to arrive (any packet it hears,
  before it can know for whom: ``RXP`` 0, not), and when the model delivers one for it ``$CACYC``, a
  ``$CARXD`` per frame and ``$CACST`` (:func:`~.micromodem_codec.cst`, version 8, padded as a Micro-Modem 2
  prints it; ``CST`` 0: not) with the link budget's figures on the modem's scales
  (:mod:`.micromodem_figures`); a packet for it that the model lost (collision, error model) gives a
  ``$CACST`` whose frames are all bad (mode 1).  At rate 0 the cycle-init minipacket is a packet of its own: ``$CARXP,0``, ``$CACYC`` and
  its ``$CACST`` (an FSK minipacket), then the data packet's ``$CARXP``, ``$CARXD`` and ``$CACST`` (what
  ``acomms``' ``wait_for_data_packet(fsk=True)`` waits for).
- **Acknowledgements.** With ``ack`` 1 to an address (in ``$CCCYC`` or a frame's ``$CCTXD``), the receiving modem answers on the channel
  (:mod:`hilgate.models.acoustic_ack`: an ACK frame after the link's ``ack_turnaround_s``); when it
  comes back the sender prints ``$CAACK,src,dest,<frame>,1`` for each frame that asked, and nothing when it does
  not (the modem does not retry: the host does).  The receiver prints ``$CATXF`` after its ``$CACST``.
- **Ping.** ``$CCMPC,src,dest`` → ``$CAMPC`` echo, ``$CAMPA,src,dest`` at the remote, and
  ``$CAMPR,dest,src,<owtt>`` back at the sender with the one-way travel time the model measured from
  the round trip (the geometry's, as ``AT?T`` is for the EvoLogics emulator), in seconds.

- **The rest of what a host library asks.**  The modem's clock (``$CCTMS``/``$CATMS``, ``$CCTMQ``/``$CATMQ``,
  the Micro-Modem 1's ``$CCCLK``/``$CCCLQ`` → ``$CACLK``; the times the modem prints follow it), user
  minipackets (``$CCMUC`` → ``$CAMUC``, ``$CAMUA`` at the far modem) and the local hardware lines
  (``$CCMEC`` → ``$CAMEC``, no line modelled).  Received minipackets (a ping, its reply, a user
  minipacket) have their ``$CACST`` too.

Not emulated: uplink requests (a ``$CCCYC`` whose source is another modem: ``$CAERR``), FDP/JANUS
packets (``$CCTFP``, ``$CCTDP``, ``$CCTJN``, ``$CCCMD``), navigation pings (``$CCPDT``, ``$CCPNT``),
hibernation, sweeps, ``$CAXST``; they answer ``$CAERR`` (docs/conformance-micromodem.md lists each).  Micro-Modem address 0
is broadcast (hilgate's 255 on the channel).
"""

from __future__ import annotations

import datetime
import logging
from dataclasses import dataclass, field
from typing import Any

from hilgate.core.backend import AppFrame, PhyEvent
from hilgate.core.endpoint import TAKEN, LinkPort
from hilgate.core.packets import BROADCAST, PacketError, Raw

from .emulated_modem import EmulatedModem
from .micromodem_codec import (CI_AIRTIME_S, MINIPACKET_S, PACKET_TYPES, RATES, RXP_TYPES, BadSentence, CycleStats,
                               ModemCodec, Sentence, cst, sentence)
from .micromodem_figures import figures
from .micromodem_settings import CONFIG, FIRMWARE, MicromodemSettings

log = logging.getLogger(__name__)

MM_BROADCAST = 0


@dataclass
class _Cycle:
    src: int
    dest: int
    rate: int
    ack: bool
    count: int
    frames: list[bytes] = field(default_factory=list)
    acks: list[bool] = field(default_factory=list)  # each frame's own ack flag ($CCTXD's)
    frame: AppFrame | None = None   # the packet on the channel, once given to the model
    timer: Any = None


class MicromodemEmulator(MicromodemSettings, EmulatedModem):
    """A WHOI Micro-Modem (the module's docstring): its data cycles, pings and minipackets, what the model
    reports of them and what it delivers; the settings a host reads and writes are :class:`.MicromodemSettings`'."""

    busy = False
    codec = ModemCodec

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        super().__init__(port, spec, scheduler)
        self.config = dict(CONFIG, SRC=port.address)
        self.cycle: _Cycle | None = None
        self.pings: set[int] = set()  # ids of ping frames awaiting their reply
        self.statistics = 0  # $CACST printed (version 8's sequence number)
        self.clock_offset = 0.0  # what $CCTMS / $CCCLK moved the modem's clock by (s)
        self._serve_hosts()

    def close(self) -> None:
        if self.cycle is not None:
            self.scheduler.cancel(self.cycle.timer)
        super().close()

    def _say(self, kind: str, *fields: object) -> None:
        self._to_hosts(sentence(kind, *fields))

    def _error(self, module: str, number: int, text: str) -> None:
        self._say("CAERR", self._clock(), module, number, text)

    # -- host → modem --------------------------------------------------------------------------------

    def _on_data(self, host: Any, data: bytes) -> None:
        codec = self._codec_of(host)
        for event in codec.receive_data(data):
            match event:
                case Sentence():
                    handler = self.COMMANDS.get(event.kind)
                    if handler is None:
                        self._error("NMEA", 1, f"Unsupported {event.kind}")
                    else:
                        handler(self, event)
                case BadSentence(reason=reason):
                    self._error("NMEA", 2, reason.capitalize())

    def _cycle_init(self, s: Sentence) -> None:
        numbers = [s.number(i) for i in range(6)]
        if None in numbers:
            self._error("CCCYC", 1, "Bad cycle init")
            return
        _, src, dest, rate, ack, count = numbers
        if rate not in RATES or not 1 <= count <= RATES[rate].frames or ack not in (0, 1) or dest > 254:
            self._error("CCCYC", 1, "Bad cycle init")
            return
        if src != self.config["SRC"]:
            self._error("CCCYC", 2, "Uplink requests are not emulated")
            return
        if self.cycle is not None:
            self._error("CCCYC", 3, "Modem busy")
            return
        self.cycle = cycle = _Cycle(src, dest, rate, bool(ack), count)
        self._say("CACYC", 0, src, dest, rate, ack, count)
        cycle.timer = self.scheduler.after_wall(self.config["CTO"] + 60.0, self._give_up, cycle)
        if rate == 0:
            ci = AppFrame(b"\x00" * 4, b"", Raw(), 0, self.port.address, self._dst(dest), self.scheduler.now())
            ci.meta = {"mm": "ci", "src": src, "dest": dest, "ack": bool(ack), "count": count}
            ci.airtime_s = CI_AIRTIME_S
            self._send(ci, cycle)
        else:
            self._request(cycle)

    def _request(self, cycle: _Cycle) -> None:
        number = len(cycle.frames) + 1
        self._say("CADRQ", self._clock(), cycle.src, cycle.dest, int(cycle.ack), RATES[cycle.rate].frame_bytes, number)
        self.scheduler.cancel(cycle.timer)
        # the host's answer takes the host's time, not the model's: at --speed 4 a model-time DTO gave a busy
        # host a quarter of the modem's 5 s, and its frame was taken as never given
        cycle.timer = self.scheduler.after_wall(self.config["DTO"], self._data_timeout, cycle)

    def _data(self, s: Sentence) -> None:
        cycle = self.cycle
        if cycle is None or cycle.frame is not None or len(cycle.frames) >= cycle.count:
            self._error("CCTXD", 4, "No data requested")
            return
        hexdata = s.field(3) or ""
        try:
            data = bytes.fromhex(hexdata)
        except ValueError:
            data = None
        if data is None or len(data) > RATES[cycle.rate].frame_bytes:
            self._data_timeout(cycle)  # the modem cannot take it: as if it had not come
            return
        ack = s.number(2) == 1 or cycle.ack
        self._say("CATXD", cycle.src, cycle.dest, int(ack), len(data))
        cycle.frames.append(data)
        cycle.acks.append(ack)
        if len(cycle.frames) < cycle.count:
            self._request(cycle)
        else:
            self._transmit(cycle)

    def _data_timeout(self, cycle: _Cycle) -> None:
        if cycle is not self.cycle or cycle.frame is not None:
            return
        self._say("CAERR", self._clock(), "DATA_TIMEOUT", len(cycle.frames) + 1, "Data not provided in time")
        if cycle.frames:
            self._transmit(cycle)  # what it has goes
        else:
            self._end(cycle)

    def _transmit(self, cycle: _Cycle) -> None:
        self.scheduler.cancel(cycle.timer)
        rate = RATES[cycle.rate]
        real = b"".join(f.ljust(rate.frame_bytes, b"\x00") for f in cycle.frames)
        frame = AppFrame(real, b"".join(cycle.frames), Raw(), 0, self.port.address, self._dst(cycle.dest),
                         self.scheduler.now())
        frame.meta = {"mm": "data", "src": cycle.src, "dest": cycle.dest, "rate": cycle.rate, "ack": cycle.ack,
                      "frames": tuple(cycle.frames), "acks": tuple(cycle.acks)}
        frame.airtime_s = rate.airtime(len(cycle.frames))
        if any(cycle.acks) and cycle.dest != MM_BROADCAST:
            frame.ack_retries = 0  # the receiving modem acknowledges; the modem itself does not retry
            frame.on_acknowledged = self._acknowledged
        cycle.frame = frame
        cycle.timer = self.scheduler.after_wall(self.config["CTO"] + 60.0, self._give_up, cycle)
        self._send(frame, cycle)

    def _send(self, frame: AppFrame, cycle: _Cycle | None) -> None:
        try:
            self.port.send(frame)
        except PacketError as exc:
            log.warning("%s: the link refused a packet: %s", self.port.id, exc)
            if cycle is not None:
                self._give_up(cycle)

    def _give_up(self, cycle: _Cycle) -> None:
        """The model never put the packet on air (the link's FIFO refused it): the cycle fails, with the
        one sentence after which every host forgets its cycle (a modem's restart)."""
        if cycle is not self.cycle:
            return
        self._error("CYCLE", 5, "Packet not transmitted")
        self._say("CAREV", self._clock(), "AUV", FIRMWARE)
        self._end(cycle)

    def _end(self, cycle: _Cycle) -> None:
        self.scheduler.cancel(cycle.timer)
        if self.cycle is cycle:
            self.cycle = None

    def _ping(self, s: Sentence) -> None:
        src, dest = s.number(0), s.number(1)
        if src is None or dest is None or dest > 254:
            self._error("CCMPC", 1, "Bad ping")
            return
        self._say("CAMPC", src, dest)
        frame = AppFrame(b"\x00\x00", b"", Raw(), 0, self.port.address, self._dst(dest), self.scheduler.now())
        frame.meta = {"mm": "ping", "src": self.config["SRC"], "dest": dest}
        frame.airtime_s = MINIPACKET_S
        if dest != MM_BROADCAST:
            frame.ack_retries = 0  # the remote's reply: the model's acknowledgement, after its turnaround
            frame.on_acknowledged = self._pinged
            self.pings.add(id(frame))
        self._send(frame, None)

    def _minipacket(self, s: Sentence) -> None:
        """``$CCMUC,src,dest,<13 bits in hex>``: a user minipacket (FSK, :data:`MINIPACKET_S` on the
        channel), echoed ``$CAMUC``; the far modem prints ``$CAMUA,src,dest,<hex>``."""
        src, dest, data = s.number(0), s.number(1), (s.field(2) or "").upper()
        try:
            value = int(data, 16)
        except ValueError:
            value = -1
        if src is None or dest is None or dest > 254 or not 0 <= value <= 0x1FFF or len(data) > 4:
            self._error("CCMUC", 1, "Bad minipacket")
            return
        self._say("CAMUC", src, dest, data)
        frame = AppFrame(value.to_bytes(2, "big"), b"", Raw(), 0, self.port.address, self._dst(dest),
                         self.scheduler.now())
        frame.meta = {"mm": "mini", "src": self.config["SRC"], "dest": dest, "data": data}
        frame.airtime_s = MINIPACKET_S
        self._send(frame, None)

    COMMANDS = {"CCCFQ": MicromodemSettings._query, "CCCFG": MicromodemSettings._configure,
                "CCALQ": MicromodemSettings._api_level, "CCCYC": _cycle_init, "CCTXD": _data, "CCMPC": _ping,
                "CCTMS": MicromodemSettings._set_time, "CCTMQ": MicromodemSettings._query_time,
                "CCCLK": MicromodemSettings._set_clock, "CCCLQ": MicromodemSettings._clock_query,
                "CCMEC": MicromodemSettings._hardware_line, "CCMUC": _minipacket}

    @staticmethod
    def _dst(dest: int) -> int:
        return BROADCAST if dest == MM_BROADCAST else dest

    # -- the model's reports ---------------------------------------------------------------------------

    def _acknowledged(self, frame: AppFrame, delivered: bool, tau: float | None) -> None:
        if not delivered:
            return  # no acknowledgement heard: the modem says nothing
        meta = frame.meta or {}
        for number, ack in enumerate(meta.get("acks", ()), 1):
            if ack:
                self._say("CAACK", meta["src"], meta["dest"], number, 1)

    def _pinged(self, frame: AppFrame, delivered: bool, tau: float | None) -> None:
        if id(frame) not in self.pings:
            return
        self.pings.discard(id(frame))
        if delivered and tau is not None:
            meta = frame.meta or {}
            self._say("CAMPR", meta["dest"], meta["src"], f"{tau:.4f}")
            # the reply is a minipacket this modem received: its statistics (from the replying modem)
            self._statistics({"src": meta["dest"], "dest": meta["src"]}, self.scheduler.now(), bad=False,
                             minipacket=True)

    def phy(self, event: PhyEvent) -> None:
        frame = event.frame
        meta = (frame.meta if frame is not None else None) or {}
        if "mm" not in meta:
            return
        cycle = self.cycle
        if event.kind == "tx":
            if cycle is not None and (frame is cycle.frame or (meta["mm"] == "ci" and cycle.frame is None)):
                if self.config["TXP"]:
                    self._say("CATXP", self._bytes_on_air(frame))
                self.scheduler.at(event.end, self._transmitted, cycle, frame)
            return
        if event.kind == "rx_start":
            # detected before it is decoded: any packet this modem hears, whoever it is for
            if self.config["RXP"]:
                psk = meta["mm"] == "data" and RATES[meta["rate"]].psk
                self._say("CARXP", RXP_TYPES["psk" if psk else "fsk"])
            return
        if event.kind == "rx_end" and event.cause is not None and meta["mm"] == "data" and self._for_me(meta):
            self._statistics(meta, event.end, bad=True)

    @staticmethod
    def _bytes_on_air(frame: AppFrame) -> int:
        """What ``$CATXP``/``$CATXF`` count: the packet's whole frames (0 for a cycle-init minipacket)."""
        return 0 if (frame.meta or {}).get("mm") == "ci" else len(frame.real)

    def _transmitted(self, cycle: _Cycle, frame: AppFrame) -> None:
        meta = frame.meta or {}
        if self.config["TXF"]:
            self._say("CATXF", self._bytes_on_air(frame))
        if meta.get("mm") == "ci":
            if cycle is self.cycle:
                self._request(cycle)
            return
        self._end(cycle)

    def _for_me(self, meta: dict) -> bool:
        return meta.get("dest") in (MM_BROADCAST, self.config["SRC"])

    # -- medium → host ---------------------------------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        meta = frame.meta or {}
        kind = meta.get("mm")
        if not self._for_me(meta):
            return TAKEN
        if kind == "ping":
            self._say("CAMPA", meta["src"], meta["dest"])
            self._statistics(meta, t, bad=False, minipacket=True)
        elif kind == "mini":
            self._say("CAMUA", meta["src"], meta["dest"], meta["data"])
            self._statistics(meta, t, bad=False, minipacket=True)
        elif kind == "ci":  # rate 0's cycle init, an FSK minipacket of its own
            self._say("CACYC", 0, meta["src"], meta["dest"], 0, int(meta.get("ack", False)), meta.get("count", 1))
            self._statistics(meta, t, bad=False, minipacket=True)
        elif kind == "data":
            frames, acks = meta["frames"], meta["acks"]
            if meta["rate"] != 0:  # (at rate 0 the cycle init said it)
                self._say("CACYC", 0, meta["src"], meta["dest"], meta["rate"], int(meta["ack"]), len(frames))
            if self.config["RXD"]:
                for number, (data, ack) in enumerate(zip(frames, acks), 1):
                    self._say("CARXD", meta["src"], meta["dest"], int(ack), number, data.hex().upper())
            self._statistics(meta, t, bad=False)
            if any(acks) and meta["dest"] != MM_BROADCAST and self.config["TXF"]:
                self._say("CATXF", 0)  # its acknowledgement went out (the model sent it on the channel)
        return TAKEN

    def _statistics(self, meta: dict, t: float, bad: bool, minipacket: bool = False) -> None:
        """``$CACST`` (version 8) of a packet heard at ``t``, from the link budget (:meth:`_figures`)."""
        if not self.config["CST"]:
            return
        rate = 0 if minipacket else meta["rate"]
        psk = RATES[rate].psk and not minipacket
        count = 1 if minipacket else (len(meta.get("frames", ())) or 1)
        toa = datetime.datetime.fromtimestamp(self._epoch() + t, datetime.timezone.utc)
        self._to_hosts(cst(CycleStats(
            mode=1 if bad else 0, toa=toa.strftime("%Y%m%d%H%M%S.%f"), rate=rate, src=meta["src"],
            dest=meta["dest"], packet_type=PACKET_TYPES["fsk_mini" if minipacket else "psk" if psk else "fsk"],
            num_frames=count, bad_frames=count if bad else 0, psk_error=3 if bad and psk else 0,
            sequence=self.statistics, **self._figures(meta["src"], t, psk))))
        self.statistics += 1

    def _figures(self, src: int, t: float, psk: bool) -> dict:
        """The link budget's reception of ``src`` at ``t`` on the modem's scales (:mod:`.micromodem_figures`)."""
        return figures(self.port.measure.reception_from(src, t), self.config["AGN"], psk)

    def state(self, ready: bool) -> None:
        pass
