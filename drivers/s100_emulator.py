"""A simulated modem that looks real: a Seatooth S100 on a pseudo-terminal or TCP, the byte pipe the real one
is, on a serial line paced as the real one: frames of the link's packet class followed by CR LF in, the same
bytes out on the other side; other bytes pass through as they are (:class:`S100Emulator`).
"""

from __future__ import annotations

from typing import Any

from hilgate.core.backend import AppFrame
from hilgate.core.endpoint import TAKEN, LinkPort
from hilgate.core.packets import BROADCAST, Decoded, Raw

from .emulated_modem import EmulatedModem, open_hosts
from .s100_codec import (CRLF, IDLE_S, PIECE, TERMINATOR, FrameHunter, InputBuffer, Notice, SerialLine, Skipped,
                         wire_class)
from .table import limits_for

LINE_AHEAD_S = 2.0  # the emulated S100 reads at most this far ahead of its serial line (then the writer waits)
WATCH_S = 0.01  # without flow control, the loop looks at its inputs at least this often (wall seconds)
HANDOVER_CAP_S = 0.25  # the kernel's hand-over delay an emulated S100 allows for at most (wall seconds)
HANDOVER_FIXED_S = 0.05  # …and allows for when the host cannot say how long its tasks waited (no PSI)


class _S100Host:
    """What the emulated S100 keeps for one host: its frame hunter, both directions of its serial
    line, its 45-byte input buffer (without flow control) and the bytes that are no frame yet."""

    def __init__(self, emulator: "S100Emulator"):
        self.hunter = FrameHunter(emulator.port.packet)
        self.line_in = SerialLine(emulator.baud, emulator.speed)
        self.line_out = SerialLine(emulator.baud, emulator.speed)
        self.buffer: InputBuffer | None = None  # made with the first bytes (the link's modem may come later)
        self.other = bytearray()  # bytes that are no frame of the link's class: passed on as they are
        self.waiting: tuple[Decoded, bytes] | None = None  # a frame and the part of its CR LF still to come
        self.after_frame = False  # the last thing sent was a frame: a CR LF now is its own (the far S100 adds one)
        self.judged_until = float("-inf")  # the latest arrival the input buffer was judged with (its own line)
        self.read_at = float("-inf")  # when bytes were last read from this host, and the host's stall then
        self.stall_then: float | None = None
        self.idle_timer = None
        self.resume_timer = None  # while reading is paused: when the line has room again


class S100Emulator(EmulatedModem):
    """A Seatooth S100 in front of a simulated link: a transparent byte pipe on a serial line.

    - **The line.** A pty takes no time per byte; the real line takes 10 bits per byte (8N1) at the
      scene's ``baud`` (default 9600, as dccomms' bridge).  Each byte the host writes is taken to
      arrive when the real line would bring it (:class:`SerialLine`), and a frame goes to the channel
      when the CR LF that ends it is in (as the real modem sends a packet; without a CR LF, after
      :data:`IDLE_S`); received frames (+ CR LF) reach the host when their last byte would.
    - **45 bytes without flow control** (``rtscts: false``, the default): the modem holds at most 45
      bytes and sends them at the air bitrate; bytes that arrive when it is full are lost, counted and
      traced (``cause: overflow``) (:class:`InputBuffer`).  With ``rtscts: true`` the modem stops the host
      instead: nothing is lost.
    - **Frames and other bytes.** Frames of the link's packet class (hunted by preamble, length and CRC)
      go on air as one frame each, as the other doors of the link see them, and come out followed by
      CR LF.  Bytes that are no such frame (text, a frame with a bad CRC, a ``+++`` line) are passed
      through as a raw frame, CR LF included, as a real S100 would carry them: when a CR LF or a frame
      ends them, after :data:`IDLE_S` without bytes, or (without flow control) 45 bytes at a time; the
      far emulated S100 writes them unchanged.  So a frame longer than 45 bytes without flow control
      crosses as 45-byte pieces, as on the real modem, and the far host's framing joins them again.
    - **A busy host loses nothing a real modem would keep.**  The emulator sees a byte when the kernel hands
      it over, not when the host wrote it: a machine that froze for a moment (a preemption, a virtual
      machine's host busy with its disk) hands over two paced pieces at once, which on a real line came
      200 ms apart.  So the 45 bytes are judged against the most favourable arrival the loop cannot rule
      out: the bytes of one read may have come at any time since the loop last looked
      (:meth:`~hilgate.core.realtime.RealtimeScheduler.input_window`; the loop is asked to look at
      least every :data:`WATCH_S`), or the kernel held them (its pty worker waits for a CPU like any
      task: at most as long as the host's tasks waited since the last read, :mod:`hilgate.core.stall`,
      capped at :data:`HANDOVER_CAP_S`), no closer than the line carries them.  Within that, each byte
      is taken to have come at the earliest moment it fits (:meth:`InputBuffer.fit`): a piece read late
      is not judged to have come late, which would leave too little room for the next one, read on time
      (a byte was lost so in 1 run of 34 beside busy test runs, before).  On a quiet host that is the
      line's own timing; a host that writes more than the modem holds at once loses the bytes the modem
      could not hold, and each overflow's trace line says the window it was judged with (``window``).
      Frames go to the channel at the times the line carries them from when they were read, as before.
    """

    busy = False
    phy = None  # (no PHY reports: hilgate.core.endpoint.Endpoint.phy)

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        super().__init__(port, spec, scheduler)
        self.baud = int(spec.get("baud", 9600))
        self.rtscts = bool(spec.get("rtscts", False))
        self.speed = scheduler.speed  # line times are wall-clock seconds
        self.piece = limits_for("s100", port.limits).piece_bytes or PIECE  # held without flow control (limits:)
        self.states: dict[Any, _S100Host] = {}
        # (with flow control nothing is judged: the loop need not look more often than it does)
        self.watch = None if self.rtscts else scheduler.watch_inputs(WATCH_S)
        self.hosts = open_hosts(spec, scheduler, self._on_data, self._on_connect, port.id)

    def _on_connect(self, host: Any) -> None:
        self.states[host] = _S100Host(self)

    # -- host → channel ---------------------------------------------------------------------------------

    def _on_data(self, host: Any, data: bytes) -> None:
        state = self.states.get(host)
        if state is None:
            state = self.states[host] = _S100Host(self)
        now = self.scheduler.now()
        line = state.line_in
        start = max(now, line.free_at)
        line.send(now, len(data))
        bt = line.byte_time
        arrivals = [start + (i + 1) * bt for i in range(len(data))]
        data, arrivals = self._kept(state, data, arrivals, now, bt)
        self._hunt(state, data, arrivals, start)
        self.scheduler.cancel(state.idle_timer)
        state.idle_timer = self.scheduler.at(line.free_at + IDLE_S * self.speed, self._idle, state)
        self._pace(host, state, now)

    def _kept(self, state: _S100Host, data: bytes, arrivals: list[float], now: float,
              bt: float) -> tuple[bytes, list[float]]:
        """The bytes of one read that the 45-byte input buffer holds (without flow control), and when each
        arrives; the others are lost, counted and traced."""
        if state.buffer is None and not self.rtscts:
            airtime = self.port.measure.airtime(1)
            if airtime:
                state.buffer = InputBuffer(1.0 / airtime, self.piece)  # drained at the air bitrate
        if state.buffer is not None:
            window = self._window(state, now)
            # written no earlier than the window allows (and after the bytes judged before them had crossed
            # the line), no later than now: each then crossed the line by its on-time arrival
            earliest = max(state.judged_until, now - window)
            fits, state.judged_until = state.buffer.fit(earliest, arrivals, bt)
            lost = fits.count(False)
            if lost:
                self.port.lost("overflow", lost, src="app", window=window)
                data = bytes(b for b, kept in zip(data, fits) if kept)
                arrivals = [t for t, kept in zip(arrivals, fits) if kept]
        return data, arrivals

    def _hunt(self, state: _S100Host, data: bytes, arrivals: list[float], start: float) -> None:
        """Frames and other bytes of one read, each to the channel when its last byte (a frame: its CR LF)
        is in; without flow control, what is held goes in 45-byte pieces."""
        if state.waiting is not None:
            # a frame whose chunk ended before its CR LF: it goes when the CR LF is in (or at once if
            # something else came instead)
            frame, need = state.waiting
            state.waiting = None
            done = len(need) if data.startswith(need) else 0
            self.scheduler.at(arrivals[done - 1] if done else start, self._event, state, frame)
        hunter = state.hunter
        base = hunter.fed  # the stream offset of data[0]
        for event, end in hunter.receive_data_at(data):
            local = end - base
            at = arrivals[local - 1] if local > 0 else start
            if isinstance(event, Decoded) and local > 0:
                # the S100 sends a packet when the CR LF that ends it is in, not at the frame's last byte
                after = data[local:local + 2]
                if after == CRLF:
                    at = arrivals[local + 1]
                elif CRLF.startswith(after):  # the chunk ends inside the frame's CR LF, or right after it
                    state.waiting = (event, CRLF[len(after):])
                    continue
            self.scheduler.at(at, self._event, state, event)
        piece = self.piece
        while state.buffer is not None and hunter.held >= piece:
            # without flow control the modem sends what it holds once it has 45 bytes, CR LF or not: a
            # longer frame goes on air in 45-byte pieces (the far host's own framing joins them again)
            local = hunter.consumed + piece - base
            self.scheduler.at(arrivals[local - 1] if local > 0 else start, self._piece, state, hunter.take(piece))

    def _window(self, state: _S100Host, now: float) -> float:
        """How long before ``now`` (model seconds) the bytes read now may have been written: what the loop
        cannot rule out, and what the kernel may have held them meanwhile (0 in virtual time)."""
        scheduler = self.scheduler
        stall = scheduler.host_stall()
        if stall is None:
            held = HANDOVER_FIXED_S * self.speed
        elif state.stall_then is None:
            held = 0.0
        else:
            held = min((stall - state.stall_then) * self.speed, now - state.read_at, HANDOVER_CAP_S * self.speed)
        state.stall_then, state.read_at = stall, now
        return scheduler.input_window() + held

    def _pace(self, host: Any, state: _S100Host, now: float) -> None:
        """Read no further ahead of the serial line than :data:`LINE_AHEAD_S`: a pty takes a flood at
        once, the real line ~1 KB/s at 9600 baud, and every byte read early is a timer (0.37 MB kept per
        MB flooded before).  Reading resumes while the line is still busy, so the bytes read later are
        timed exactly as if they had been read at once; meanwhile the writer waits, as on a real port."""
        ahead = LINE_AHEAD_S * self.speed
        if state.line_in.free_at - now > ahead and state.resume_timer is None:
            host.pause()
            state.resume_timer = self.scheduler.at(state.line_in.free_at - ahead, self._resume, host, state)

    def _resume(self, host: Any, state: _S100Host) -> None:
        state.resume_timer = None
        host.resume()

    def _event(self, state: _S100Host, event: object) -> None:
        if isinstance(event, Decoded):
            self._send_other(state)  # what came before the frame goes first
            packet = self.port.packet
            real = event.real if not isinstance(packet, Raw) else event.payload
            # S100 frames carry no address of their own (a DataLinkFrame's header does): broadcast
            self.port.send(AppFrame(real, event.payload, packet, 0, self.port.address, event.dst,
                                    self.scheduler.now()))
            state.after_frame = True
            return
        after_frame, state.after_frame = state.after_frame, False
        if isinstance(event, Skipped):
            if event.reason == TERMINATOR and not state.other and after_frame:
                state.after_frame = True  # (its CR and LF may come in two reads)
                return  # the CR LF after a frame (not a CR or LF of a long frame's payload, sent in pieces)
            state.other += event.data
            if state.other.endswith(CRLF):
                self._send_other(state)
            elif state.buffer is not None and len(state.other) >= self.piece:
                self._piece(state, b"")
        elif isinstance(event, Notice):
            state.other += event.data  # as it came: a notice cut short by a frame has no CR LF of its own
            self._send_other(state)

    def _piece(self, state: _S100Host, data: bytes) -> None:
        """45 bytes without flow control: what is pending goes as packets of 45 bytes (the rest waits)."""
        state.after_frame = False
        state.other += data
        piece = self.piece
        while len(state.other) >= piece:
            self._send_raw(bytes(state.other[:piece]))
            del state.other[:piece]

    def _idle(self, state: _S100Host) -> None:
        """Nothing came for :data:`IDLE_S`: a frame still waiting for its CR LF goes (the modem's
        timeout), and what the hunter holds will not become a frame: send it as it is."""
        state.idle_timer = None
        if state.waiting is not None:
            self._event(state, state.waiting[0])
            state.waiting = None
        state.other += state.hunter.flush()
        self._send_other(state)

    def _send_other(self, state: _S100Host) -> None:
        data = bytes(state.other)
        state.other.clear()
        if data:
            self._send_raw(data)

    def _send_raw(self, data: bytes) -> None:
        """Bytes that are no frame, on air as they are (CR LF included): the far S100 writes them unchanged."""
        frame = AppFrame(data, data, Raw(), 0, self.port.address, BROADCAST, self.scheduler.now())
        frame.meta = {"s100": "raw"}
        self.port.send(frame)

    # -- channel → host ---------------------------------------------------------------------------------

    def deliver(self, frame: AppFrame, t: float) -> str:
        packet = self.port.packet
        wire = wire_class(packet)
        if (frame.meta or {}).get("s100") == "raw":
            data = frame.payload  # another S100's bytes, as they were (with their CR LF, if they had one)
        elif isinstance(packet, Raw):
            data = wire.encode(frame.payload) + CRLF
        elif frame.packet.name == packet.name:
            data = frame.real + CRLF
        else:
            data = packet.encode(frame.payload, src=frame.src, dst=frame.dst) + CRLF
        for host, state in list(self.states.items()):
            done = state.line_out.send(t, len(data))
            self.scheduler.at(done, host.write, data)  # the host has the whole line when its last byte is in
        return TAKEN

    def state(self, ready: bool) -> None:
        pass

    def close(self) -> None:
        for state in self.states.values():
            self.scheduler.cancel(state.idle_timer)
            self.scheduler.cancel(state.resume_timer)
        self.scheduler.unwatch_inputs(self.watch)
        super().close()
