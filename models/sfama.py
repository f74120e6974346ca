"""Slotted FAMA (Molins & Stojanovic 2006), as UWSim-NET evaluated it through Aqua-Sim NG.

Time is divided into slots shared by every node (slot k starts at k·slot from time 0).  A slot is
long enough for a control frame sent at its start to reach anyone in range before it ends:

    slot = τ_max + max(T_RTS, T_CTS, T_ACK) + tx_delay        (τ_max = min_delay + max_range / speed)

Molins & Stojanovic size the slot as τ_max + γ, γ "the transmission time of a CTS", with every
control frame as long as a CTS; what the rule guarantees is that a control frame sent at a slot
start is heard within that slot.  The ACK is such a frame (sent at a slot start, awaited by the
end of its slot), so when ``ack_bytes`` exceeds the RTS/CTS the slot is sized from the ACK:
otherwise every ACK would end after the deadline and each delivered frame would be sent again
until given up.  With the default sizes (all 5 bytes) this is the paper's slot.

The exchange, with the RTS sent at the start of slot k:

- k: RTS; the addressed receiver, if it is free and not silenced, answers
- k+1: CTS;
- k+2: DATA, taking n = ceil((tx_delay + T_DATA + τ_max) / slot) slots;
- k+2+n: ACK from the receiver; the sender expects it by the end of that slot.

A node that overhears an RTS or a CTS meant for someone else stays silent until the end of the ACK
slot of the exchange it announces (the control frames carry the data length); so does the receiver
that granted the exchange with its CTS.  No CTS by the start
of slot k+2, or no ACK ⇒ back off 1..``max_backoff_slots`` slots (uniform) and start again with an
RTS; after ``max_retries`` retries the frame is given up.  Broadcast data goes out at a slot start
without RTS/CTS or ACK.  Frames go on air ``tx_delay`` after the slot start (the modem's intrinsic
delay); with ``tx_delay_s: 0`` exactly on it.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from .frame import ACK, BROADCAST, CTS, DATA, RTS
from .mac import HoldingMac, MacHost, Param

if TYPE_CHECKING:
    from .frame import Frame

EPS = 1e-9
DECIDE = 1e-9  # how long after a boundary a missing answer is declared missing
IDLE, WAIT_CTS, SEND_DATA, WAIT_ACK, BACKOFF = "idle", "wait_cts", "send_data", "wait_ack", "backoff"


class SFama(HoldingMac):
    name = "s-fama"
    hears_all = True  # overhearing RTS/CTS is the protocol
    PARAMETERS = {
        "max_range_m": Param("number", None, minimum=0.0, doc="default: the modem's range"),
        "max_backoff_slots": Param("integer", 4, minimum=1),
        "rts_bytes": Param("integer", 5, minimum=1),
        "cts_bytes": Param("integer", 5, minimum=1),
        "ack_bytes": Param("integer", 5, minimum=1),
        "max_retries": Param("integer", 5, minimum=0),
    }

    def __init__(self, max_range_m: float | None = None, max_backoff_slots: int = 4, rts_bytes: int = 5,
                 cts_bytes: int = 5, ack_bytes: int = 5, max_retries: int = 5):
        super().__init__(max_range_m, max_retries)
        self.max_backoff_slots = max_backoff_slots
        self.rts_bytes = rts_bytes
        self.cts_bytes = cts_bytes
        self.ack_bytes = ack_bytes
        self.silent_until = 0.0
        self.rts_slot = 0
        self.answering = 0  # CTS/ACK exchanges this node has promised as a receiver

    def attach(self, modem: MacHost) -> None:
        super().attach(modem)
        self.tau_max = modem.tau_at(self.max_range("give max_range_m"))
        control = max(self.rts_bytes, self.cts_bytes, self.ack_bytes)  # see the module's docstring
        self.slot = self.tau_max + modem.airtime(control) + modem.tx_delay

    @classmethod
    def check(cls, modem: Any, params: dict[str, Any]) -> str | None:
        if params.get("max_range_m") is None and modem.range_m[1] == float("inf"):
            return "s-fama needs max_range_m when the link's range_m is unlimited (it sets the slot length)"
        return None

    # -- the slot grid --------------------------------------------------------------------------

    def slot_index(self, t: float) -> int:
        """The slot ``t`` is in (a time on a boundary belongs to the slot it starts)."""
        return math.floor(t / self.slot + EPS)

    def boundary(self, k: int) -> float:
        return k * self.slot

    def next_boundary(self, t: float) -> float:
        """The first slot start at or after ``t``."""
        return self.boundary(math.ceil(t / self.slot - EPS))

    def data_slots(self, size: int) -> int:
        modem = self.modem
        return max(1, math.ceil((modem.tx_delay + modem.airtime(size) + self.tau_max) / self.slot - EPS))

    def _at(self, t: float, fn, *args) -> None:
        if self.timer is not None:
            self.modem.clock.cancel(self.timer)
        self.timer = self.modem.clock.at(t, fn, *args)

    # -- sender ---------------------------------------------------------------------------------

    def on_enqueue(self) -> None:
        if self.state == IDLE and self.timer is None:
            self._plan()

    def _plan(self, not_before: float | None = None) -> None:
        """Take the next frame (if none is held) and aim for the next usable slot start."""
        modem = self.modem
        if self.current is None:
            if not modem.fifo:
                self.state = IDLE
                self.timer = None
                return
            self.current = modem.fifo_pop()
            self.attempts = 0
        now = modem.clock.now()
        start = max(now, self.silent_until, not_before if not_before is not None else now)
        self.state = IDLE
        self._at(self.next_boundary(start), self._slot_start)

    def _slot_start(self) -> None:
        modem = self.modem
        self.timer = None
        now = modem.clock.now()
        if now < self.silent_until - EPS or modem.phy_busy or self.answering:
            self._plan(not_before=max(self.silent_until, now + EPS))
            return
        frame = self.current
        if frame.dst_addr == BROADCAST:
            self.state = SEND_DATA
            modem.transmit(frame)
            return
        rts = modem.control_frame(RTS, self.rts_bytes, frame.dst_addr, frame.dst_link, frame)
        self.state = WAIT_CTS
        modem.transmit(rts)
        self.rts_slot = self.slot_index(now)
        # Failure is decided just after the boundary, once a CTS arriving exactly on it has been heard.
        self._at(self.boundary(self.rts_slot + 2) + DECIDE, self._no_cts)

    def _no_cts(self) -> None:
        self.timer = None
        if self.state == WAIT_CTS:
            self._retry("no_cts")

    def _send_data(self) -> None:
        self.timer = None
        self.state = SEND_DATA
        self.modem.transmit(self.current)
        n = self.data_slots(self.current.size)
        self._at(self.boundary(self.rts_slot + 3 + n) + DECIDE, self._ack_missing)

    def _ack_missing(self) -> None:
        self.timer = None
        if self.state == WAIT_ACK or self.state == SEND_DATA:
            self._retry("no_ack")

    def _retry(self, why: str) -> None:
        modem = self.modem
        now = modem.clock.now()
        self.attempts += 1
        if self.attempts > self.max_retries:
            modem.observer.mac(now, modem, self.current, "giveup", attempts=self.attempts, cause=why)
            self._done()
            return
        if why == "no_ack":
            modem.observer.mac(now, modem, self.current, "retx", attempt=self.attempts)
        slots = modem.rng.randint(1, self.max_backoff_slots)
        modem.observer.mac(now, modem, self.current, "backoff", cause=why, slots=slots)
        self.state = BACKOFF
        self._at(self.boundary(self.slot_index(now) + slots), self._backoff_over)

    def _backoff_over(self) -> None:
        self.timer = None
        self._plan()

    def _next(self) -> None:
        self._plan()

    def on_tx_done(self, frame: "Frame") -> None:
        if frame is self.current and self.state == SEND_DATA:
            if frame.dst_addr == BROADCAST:
                self._done()
            else:
                self.state = WAIT_ACK

    # -- receiver and overhearing -----------------------------------------------------------------

    def on_frame(self, frame: "Frame", cause: str | None, addressed: bool) -> None:
        if cause is not None:
            return
        modem = self.modem
        now = modem.clock.now()
        mine = addressed and frame.dst_addr == modem.address
        if frame.kind in (RTS, CTS) and not mine:
            self._overheard(frame, now)
            return
        if not mine and frame.kind != DATA:
            return
        if frame.kind == RTS:
            self._on_rts(frame, now)
        elif frame.kind == CTS:
            modem.consume(frame)
            if self.state == WAIT_CTS and frame.ref is self.current:
                self.state = SEND_DATA
                self._at(self.boundary(self.rts_slot + 2), self._send_data)  # maybe this very instant
        elif frame.kind == ACK:
            modem.consume(frame)
            if self.state in (WAIT_ACK, SEND_DATA) and frame.ref is self.current:
                self._done()
        elif frame.kind == DATA and addressed:
            if frame.dst_addr != BROADCAST and frame.dst_addr == modem.address:
                ack = modem.control_frame(ACK, self.ack_bytes, frame.src_addr, frame.src_link, frame)
                self._answer(self.next_boundary(now), ack)
            if self.duplicates.seen(frame):
                modem.observer.mac(now, modem, frame, "dup")
                return
            modem.deliver(frame)

    def _overheard(self, frame: "Frame", now: float) -> None:
        """An RTS or CTS for another modem: stay silent until the end of the ACK slot of the announced
        exchange."""
        j = self.slot_index(now - EPS)
        n = self.data_slots(frame.ref.size)
        until = self.boundary(j + (3 if frame.kind == RTS else 2) + n)
        if until > self.silent_until:
            self.silent_until = until

    def _on_rts(self, frame: "Frame", now: float) -> None:
        """An RTS for this modem: a CTS at the next slot boundary, unless busy or silenced."""
        modem = self.modem
        modem.consume(frame)
        if now < self.silent_until - EPS or self.state in (WAIT_CTS, SEND_DATA, WAIT_ACK) or self.answering:
            return  # busy or silenced: no CTS
        cts = modem.control_frame(CTS, self.cts_bytes, frame.src_addr, frame.src_link, frame.ref)
        # the slot is sized so that an RTS from up to max_range has fully arrived by the next
        # boundary, possibly exactly on it: the CTS goes at that boundary
        at = self.next_boundary(now)
        self._answer(at, cts)
        # having granted the exchange, keep quiet until its ACK slot is over
        j = self.slot_index(at)
        self.silent_until = max(self.silent_until, self.boundary(j + 2 + self.data_slots(frame.ref.size)))

    def _answer(self, at: float, frame: "Frame") -> None:
        """Send a CTS or ACK at the slot start ``at`` (a receiver's promise; it defers its own RTS)."""
        self.answering += 1
        self.modem.clock.at(at, self._send_answer, frame)

    def _send_answer(self, frame: "Frame") -> None:
        self.answering -= 1
        modem = self.modem
        if modem.phy_busy:
            return  # half duplex: the answer cannot go out; the sender will retry
        modem.transmit(frame)
