"""The modem's own acknowledgements: an ACK frame on the channel, retries, and the delivery report.

An EvoLogics S2C answers an instant message sent with ``ack`` (and a burst) with an acknowledgement
frame of its own; it is not a MAC protocol (any MAC, or none, may run underneath) but part of the
modem, so it lives beside the modem rather than in ``macs.py``.  Why it is modelled as a frame at all:
a real ACK takes air time, collides, is lost to the error model and beyond range like any frame, and
a driver sees the consequences (late ``DELIVEREDIM``, ``FAILEDIM`` after retries, duplicate ``RECVIM``).

The exchange, for a data frame that asks for an ACK with ``retries`` allowed (``frame.ack``):

- the sender puts it on air as any frame (FIFO, MAC, ``tx_delay``); its transmission ends at t_off;
- the addressed receiver that hears it good at t_e answers at t_e + ``ack_turnaround_s`` with an ACK
  of ``ack_bytes`` bytes, straight to its PHY (no FIFO, no MAC, no ``tx_delay``: the turnaround is the
  modem's whole reaction time); if its PHY is busy then, the ACK goes as soon as it is free;
- the receiver hands an application's frame up every time it hears it good: a retransmission whose
  ACK was lost is delivered again, as the reference says real receivers see duplicates (traced ``dup``);
  a built-in flow's duplicate is traced ``dup`` and not counted again;
- the sender waits, after each transmission, ``wait_s`` = 2·τ_max + ``ack_turnaround_s`` + T_ack +
  ``rx_delay_s`` + :data:`GUARD_S`, τ_max the propagation delay at the sender's maximum range: never
  shorter than a round trip at maximum range.  An ACK heard good in time reports *delivered* at its
  end + ``rx_delay_s``; otherwise the frame goes back to the head of the FIFO (``retx``), up to
  ``retries`` times, then *failed* (``giveup``) when the last wait ends.

With zero jitter and ``mac: none`` the delivery report of an ACKed frame sent at t0 on an idle modem is
exactly t0 + tx_delay + T + τ + ack_turnaround + T_ack + τ' + rx_delay (τ' the way back when the ACK
leaves), and a failure is reported at t0 + (retries + 1)·(tx_delay + T + wait_s).  The one-way
propagation time a modem reports after an exchange (``AT?T``) is measured the way a modem measures it:
half the round trip less the turnaround and the ACK's air time.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Callable

from .frame import BROADCAST, DATA
from .mac import Duplicates

if TYPE_CHECKING:
    from .frame import Frame
    from .modem import SimModem

MODEM_ACK = "modem_ack"
"""The kind of the modem's own ACK frames (a MAC's are ``ack``): traced with ``"kind": "modem_ack"``."""

GUARD_S = 0.001
"""Margin after the latest instant an ACK can end at the sender, so that an ACK from the maximum range
is never judged after its own deadline (equal floating-point times would otherwise race)."""

Outcome = Callable[["Frame", bool, "float | None"], Any]
"""``on_outcome(frame, delivered, one_way_tau_s)``: the report of an ACKed frame (tau None on failure)."""


class Acknowledger:
    """One modem's side of acknowledged frames: what it waits for as a sender, what it owes as a receiver.

    The modem calls :meth:`sent` when a frame leaves the air, :meth:`heard_data` for every good data
    frame addressed to it, :meth:`heard_ack` for every ACK addressed to it, and :meth:`next_owed` when
    its PHY frees."""

    def __init__(self, modem: "SimModem"):
        self.modem = modem
        self.on_outcome: Outcome | None = None  # set by whoever sends ACKed frames (the backend)
        self.waiting: dict[int, _Wait] = {}  # frame id → the wait for its ACK
        self.owed: list["Frame"] = []  # ACKs due while the PHY was busy, in order
        self.duplicates = Duplicates()  # acknowledged frames heard before (their ACK was lost)

    @property
    def busy(self) -> bool:
        """An ACKed frame is on its way and not reported yet: the modem is not idle."""
        return bool(self.waiting)

    def wait_s(self) -> float:
        """How long after a transmission's end the sender waits for its ACK (see the module doc)."""
        modem = self.modem
        max_range = modem.range_m[1]
        tau = modem.tau_at(max_range) if math.isfinite(max_range) else 0.0
        return 2.0 * tau + modem.params.ack_turnaround_s + modem.airtime(modem.params.ack_bytes) \
            + modem.params.rx_delay_s + GUARD_S

    # -- sender ---------------------------------------------------------------------------------

    def wants_ack(self, frame: "Frame") -> bool:
        return frame.ack is not None and frame.kind == DATA and frame.dst_addr != BROADCAST

    def sent(self, frame: "Frame", t_end: float) -> None:
        """An ACKed frame left the air at ``t_end``: wait for its ACK."""
        wait = self.waiting.get(frame.id)
        if wait is None:
            wait = self.waiting[frame.id] = _Wait(frame)
        wait.t_off = t_end
        limit = self.wait_s()
        if not math.isfinite(self.modem.range_m[1]):
            # unlimited range: no maximum round trip exists; wait for the round trip to the addressee now
            tau = self._tau_to(frame, t_end)
            limit += 2.0 * (tau or 0.0)
        wait.timer = self.modem.clock.at(t_end + limit, self._timeout, frame)

    def heard_ack(self, ack: "Frame") -> None:
        """A good ACK for this modem: the frame it answers is delivered (after the rx delay)."""
        modem = self.modem
        modem.consume(ack)
        wait = self.waiting.get(ack.ref.id) if ack.ref is not None else None
        if wait is None or wait.timer is None:
            return  # an ACK of a retransmission whose report is done, or that came after the deadline
        modem.clock.cancel(wait.timer)
        wait.timer = None
        now = modem.clock.now()
        params = modem.params
        tau = max(0.0, (now - wait.t_off - params.ack_turnaround_s - modem.airtime(ack.size)) / 2.0)
        if params.rx_delay_s > 0.0:
            modem.clock.at(now + params.rx_delay_s, self._report, wait.frame, True, tau)
        else:
            self._report(wait.frame, True, tau)

    def _timeout(self, frame: "Frame") -> None:
        modem = self.modem
        wait = self.waiting.get(frame.id)
        if wait is None:
            return
        wait.timer = None
        now = modem.clock.now()
        if wait.attempts >= frame.ack:
            modem.observer.mac(now, modem, frame, "giveup", attempts=wait.attempts + 1, cause="no_ack")
            self._report(frame, False, None)
            return
        wait.attempts += 1
        modem.observer.mac(now, modem, frame, "retx", attempt=wait.attempts, cause="no_ack")
        modem.requeue(frame)

    def _report(self, frame: "Frame", delivered: bool, tau: float | None) -> None:
        if self.waiting.pop(frame.id, None) is None:
            return
        if self.on_outcome is not None:
            self.on_outcome(frame, delivered, tau)
        self.modem.check_idle()

    def _tau_to(self, frame: "Frame", t: float) -> float | None:
        modem = self.modem
        other = modem.medium.modem_by_address(modem.tx_channel, frame.dst_addr)
        return None if other is None else modem.medium.propagation_delay(modem.radio, other.radio, t)

    def forget(self) -> None:
        """The modem closes: no report will come for what is still waiting."""
        for wait in self.waiting.values():
            if wait.timer is not None:
                self.modem.clock.cancel(wait.timer)
        self.waiting.clear()
        self.owed.clear()

    # -- receiver -------------------------------------------------------------------------------

    def heard_data(self, frame: "Frame") -> bool:
        """A good frame addressed to this modem that asks for an ACK: answer after the turnaround.
        True when it was heard before (a retransmission whose ACK was lost), traced as ``dup``."""
        modem = self.modem
        ack = modem.new_frame(frame.src_link, frame.src_addr, modem.params.ack_bytes, flow=frame.flow,
                              kind=MODEM_ACK, ref=frame)
        modem.clock.at(modem.clock.now() + modem.params.ack_turnaround_s, self._answer, ack)
        if self.duplicates.seen(frame):
            modem.observer.mac(modem.clock.now(), modem, frame, "dup")
            return True
        return False

    def _answer(self, ack: "Frame") -> None:
        if self.modem.phy_busy:
            self.owed.append(ack)
        else:
            self.modem.transmit_now(ack)

    def next_owed(self) -> "Frame | None":
        return self.owed.pop(0) if self.owed else None


class _Wait:
    __slots__ = ("frame", "attempts", "t_off", "timer")

    def __init__(self, frame: "Frame"):
        self.frame = frame
        self.attempts = 0  # retransmissions so far
        self.t_off = 0.0
        self.timer: Any = None
