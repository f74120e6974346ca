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
- **The receiver** prints ``$CACYC``, a ``$CARXD`` per frame and ``$CACST`` (statistics from the link
  budget: the RSSI of :mod:`hilgate.models.link_budget`, SNR against :data:`NOISE_DB`, integrity as the
  data quality factor, the closing speed as Doppler) when the model delivers it; a packet for it that
  the model lost (collision, error model) gives a ``$CACST`` whose frames are all bad (mode 1).
- **Acknowledgements.** With ``ack`` 1 to an address (in ``$CCCYC`` or a frame's ``$CCTXD``), the receiving modem answers on the channel
  (:mod:`hilgate.models.acoustic_ack`: an ACK frame after the link's ``ack_turnaround_s``); when it
  comes back the sender prints ``$CAACK,src,dest,<frame>,1`` for each frame that asked, and nothing when it does
  not (the modem does not retry: the host does).  The receiver prints ``$CATXF`` after its ``$CACST``.
- **Ping.** ``$CCMPC,src,dest`` → ``$CAMPC`` echo, ``$CAMPA,src,dest`` at the remote, and
  ``$CAMPR,dest,src,<owtt>`` back at the sender with the one-way travel time the model measured from
  the round trip (the geometry's, as ``AT?T`` is for the EvoLogics emulator), in seconds.

Not emulated: uplink requests (a ``$CCCYC`` whose source is another modem: ``$CAERR``), FDP/JANUS
packets (``$CCTFP``, ``$CCTDP``, ``$CCTJN``), navigation pings, the modem's clock, hibernation, ``$CAXST``;
they answer ``$CAERR``.  Micro-Modem address 0 is broadcast (hilgate's 255 on the channel).
"""

from __future__ import annotations

import datetime
import logging
from dataclasses import dataclass, field
from typing import Any

from hilgate.core.backend import AppFrame, PhyEvent
from hilgate.core.endpoint import TAKEN, LinkPort
from hilgate.core.packets import BROADCAST, PacketError, Raw

from .emulators import EmulatedModem
from .micromodem_codec import (CI_AIRTIME_S, MINIPACKET_S, RATES, BadSentence, ModemCodec, Sentence, hhmmss,
                               sentence)

log = logging.getLogger(__name__)

FIRMWARE = "2.0.0"
NOISE_DB = -100  # the noise level $CACST reports (dB, the scale of the link budget's RSSI): hilgate's constant
CARRIER_HZ, BANDWIDTH_HZ = 25000, 5000  # the preset's band (22.5-27.5 kHz)
MM_BROADCAST = 0
CONFIG = {"SRC": 0, "ASD": 0, "BND": 3, "CTO": 10, "DTO": 5, "PCM": 0, "REV": 0, "TAT": 50, "XST": 0}
"""The configuration parameters the emulator keeps (``DTO``: seconds the modem waits for a frame;
``CTO``: seconds a cycle may take in all)."""


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


class MicromodemEmulator(EmulatedModem):
    """A WHOI Micro-Modem (the module's docstring)."""

    busy = False
    codec = ModemCodec

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        super().__init__(port, spec, scheduler)
        self.config = dict(CONFIG, SRC=port.address)
        self.cycle: _Cycle | None = None
        self.pings: set[int] = set()  # ids of ping frames awaiting their reply
        self._serve_hosts()

    def close(self) -> None:
        if self.cycle is not None:
            self.scheduler.cancel(self.cycle.timer)
        super().close()

    def _say(self, kind: str, *fields: object) -> None:
        self._to_hosts(sentence(kind, *fields))

    def _clock(self) -> str:
        return hhmmss(self._epoch() + self.scheduler.now())

    def _epoch(self) -> float:
        return self.scheduler.epoch_ns / 1e9

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

    def _query(self, s: Sentence) -> None:
        name = (s.field(0) or "").upper()
        if name == "ALL":
            for key, value in self.config.items():
                self._say("CACFG", key, value)
        elif name == "INFO":
            self._say("CACFG", "info.firmware_version", FIRMWARE)
        elif name in self.config:
            self._say("CACFG", name, self.config[name])
        else:
            self._error("CCCFQ", 3, f"Unknown parameter {name}")

    def _configure(self, s: Sentence) -> None:
        name = (s.field(0) or "").upper()
        value = s.number(1)
        if name not in self.config or value is None:
            self._error("CCCFG", 3, f"Bad parameter {name}")
            return
        if name == "SRC":
            if not 1 <= value <= 254:
                self._error("CCCFG", 4, "SRC out of range")
                return
            self.port.set_address(value)
        self.config[name] = value
        self._say("CACFG", name, value)

    def _api_level(self, s: Sentence) -> None:
        self._say("CAALQ", 0, 11)

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
            ci.meta = {"mm": "ci", "src": src, "dest": dest}
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

    COMMANDS = {"CCCFQ": _query, "CCCFG": _configure, "CCALQ": _api_level, "CCCYC": _cycle_init, "CCTXD": _data,
                "CCMPC": _ping}

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

    def phy(self, event: PhyEvent) -> None:
        frame = event.frame
        meta = (frame.meta if frame is not None else None) or {}
        if "mm" not in meta:
            return
        cycle = self.cycle
        if event.kind == "tx":
            if cycle is not None and (frame is cycle.frame or (meta["mm"] == "ci" and cycle.frame is None)):
                self.scheduler.at(event.end, self._transmitted, cycle, frame)
            return
        if event.kind == "rx_end" and event.cause is not None and meta["mm"] == "data" and self._for_me(meta):
            self._statistics(meta, event.end, bad=True)

    def _transmitted(self, cycle: _Cycle, frame: AppFrame) -> None:
        meta = frame.meta or {}
        if meta.get("mm") == "ci":
            self._say("CATXF", 0)
            if cycle is self.cycle:
                self._request(cycle)
            return
        self._say("CATXF", len(frame.real))
        self._end(cycle)

    def _for_me(self, meta: dict) -> bool:
        return meta.get("dest") in (MM_BROADCAST, self.config["SRC"])

    # -- medium → host ---------------------------------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        meta = frame.meta or {}
        kind = meta.get("mm")
        if kind == "ping" and self._for_me(meta):
            self._say("CAMPA", meta["src"], meta["dest"])
        elif kind == "data" and self._for_me(meta):
            frames, acks = meta["frames"], meta["acks"]
            self._say("CACYC", 0, meta["src"], meta["dest"], meta["rate"], int(meta["ack"]), len(frames))
            for number, (data, ack) in enumerate(zip(frames, acks), 1):
                self._say("CARXD", meta["src"], meta["dest"], int(ack), number, data.hex().upper())
            self._statistics(meta, t, bad=False)
            if any(acks) and meta["dest"] != MM_BROADCAST:
                self._say("CATXF", 0)  # its acknowledgement went out (the model sent it on the channel)
        return TAKEN

    def _statistics(self, meta: dict, t: float, bad: bool) -> None:
        """``$CACST`` (version 6) of a packet heard at ``t``: the link budget's figures."""
        heard = self.port.reception_from(meta["src"], t)
        rssi = heard.rssi_db if heard is not None else NOISE_DB
        integrity = heard.integrity if heard is not None else 0
        velocity = heard.velocity_mps if heard is not None else 0.0
        snr = rssi - NOISE_DB
        count = len(meta.get("frames", ())) or 1
        toa = datetime.datetime.fromtimestamp(self._epoch() + t, datetime.timezone.utc)
        rate = meta["rate"]
        self._say("CACST", 6, 1 if bad else 0, toa.strftime("%Y%m%d%H%M%S.%f"), 0, 0, rssi, 0, rssi, 250,
                  0, 0, 0, 0, rate, meta["src"], meta["dest"], 0, 3 if RATES[rate].psk else 1, count,
                  count if bad else 0, snr, f"{snr:.1f}", f"{snr:.1f}", f"{snr:.1f}", f"{-snr / 2:.1f}",
                  min(255, max(0, integrity)), f"{velocity:.1f}", NOISE_DB, CARRIER_HZ, BANDWIDTH_HZ)

    def state(self, ready: bool) -> None:
        pass
