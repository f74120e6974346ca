"""CS-ALOHA: carrier-sense ALOHA with acknowledgements, as UWSim-NET evaluated it through Aqua-Sim NG.

A node sends the head of its FIFO only when it hears nothing; if the channel is busy it backs off a
random time in ``backoff_s`` and listens again.  The addressed receiver answers a good data frame
with an ACK at once (no carrier sense for ACKs); without an ACK within ``ack_timeout_s`` of the end
of its transmission the sender backs off and retransmits, up to ``max_retries`` times, then gives up.
Receivers deliver a retransmitted frame once.  Broadcasts are not acknowledged.  With ``acks: false``
it is carrier sense alone (non-persistent CSMA), for modems that have no acknowledgements (S100).

The default ACK timeout covers the worst case: the data frame's end reaches a receiver at the
maximum range (τ_max), the receiver's intrinsic delay, the ACK's airtime, its way back (τ_max), plus
10 % and 1 ms of margin.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .frame import ACK, BROADCAST, DATA
from .mac import HoldingMac, MacHost, Param

if TYPE_CHECKING:
    from .frame import Frame

IDLE, BACKOFF, SENDING, WAIT_ACK = "idle", "backoff", "sending", "wait_ack"


class CsAloha(HoldingMac):
    name = "cs-aloha"
    hears_all = False
    PARAMETERS = {
        "ack_timeout_s": Param("number", None, minimum=0.0, doc="default: from max range, bitrate, ACK length"),
        "max_retries": Param("integer", 3, minimum=0),
        "backoff_s": Param("pair", (0.1, 1.0), minimum=0.0, doc="uniform random backoff [min, max]"),
        "ack_bytes": Param("integer", 5, minimum=1),
        "max_range_m": Param("number", None, minimum=0.0, doc="default: the modem's range"),
        "acks": Param("boolean", True, doc="false: carrier sense only, no ACK and no retransmission"),
    }

    def __init__(self, ack_timeout_s: float | None = None, max_retries: int = 3,
                 backoff_s: tuple[float, float] = (0.1, 1.0), ack_bytes: int = 5, max_range_m: float | None = None,
                 acks: bool = True):
        super().__init__(max_range_m, max_retries)
        self.acks = acks
        self.ack_timeout_param = ack_timeout_s
        self.backoff_s = backoff_s
        self.ack_bytes = ack_bytes
        self.pending_acks: list[Frame] = []

    def attach(self, modem: MacHost) -> None:
        super().attach(modem)
        if not self.acks:
            self.ack_timeout = 0.0
        else:
            self.ack_timeout = self.ack_timeout_param if self.ack_timeout_param is not None else self.default_timeout()

    @classmethod
    def check(cls, modem: Any, params: dict[str, Any]) -> str | None:
        if params.get("acks") is False:
            return None
        if params.get("ack_timeout_s") is None and params.get("max_range_m") is None \
                and modem.range_m[1] == float("inf"):
            return "cs-aloha needs ack_timeout_s or max_range_m when the link's range_m is unlimited"
        return None

    def default_timeout(self) -> float:
        modem = self.modem
        tau = modem.tau_at(self.max_range("give ack_timeout_s or max_range_m"))
        return 1.1 * (2 * tau + modem.tx_delay + modem.airtime(self.ack_bytes)) + 0.001

    # -- sending -------------------------------------------------------------------------------

    def on_enqueue(self) -> None:
        if self.state == IDLE:
            self._try_send()

    def _try_send(self) -> None:
        modem = self.modem
        self.timer = None
        if self.pending_acks:
            if not modem.phy_busy:
                modem.transmit(self.pending_acks.pop(0))
            return  # the data frame waits for the PHY; on_tx_done resumes
        if modem.phy_busy:
            return
        if self.current is None:
            if not modem.fifo:
                self.state = IDLE
                return
            self.current = modem.fifo_pop()
            self.attempts = 0
        if modem.channel_busy():
            self._backoff("busy")
            return
        self.state = SENDING
        modem.transmit(self.current)

    def _backoff(self, why: str) -> None:
        modem = self.modem
        low, high = self.backoff_s
        wait = modem.rng.uniform(low, high)
        self.state = BACKOFF
        modem.observer.mac(modem.clock.now(), modem, self.current, "backoff", cause=why, wait_s=round(wait, 9))
        self.timer = modem.clock.at(modem.clock.now() + wait, self._try_send)

    def on_tx_done(self, frame: "Frame") -> None:
        modem = self.modem
        if frame is self.current and self.state == SENDING:
            if frame.dst_addr == BROADCAST or not self.acks:
                self._done()
                return
            self.state = WAIT_ACK
            self.timer = modem.clock.at(modem.clock.now() + self.ack_timeout, self._ack_timeout)
        if self.pending_acks and not modem.phy_busy:
            modem.transmit(self.pending_acks.pop(0))
        elif self.timer is None and self.state in (IDLE, BACKOFF):
            self._try_send()  # a backoff that ended while an ACK was on air resumes here

    def _ack_timeout(self) -> None:
        modem = self.modem
        self.timer = None
        self.attempts += 1
        if self.attempts > self.max_retries:
            modem.observer.mac(modem.clock.now(), modem, self.current, "giveup", attempts=self.attempts)
            self._done()
            return
        modem.observer.mac(modem.clock.now(), modem, self.current, "retx", attempt=self.attempts)
        self._backoff("no_ack")

    def _next(self) -> None:
        self._try_send()

    # -- receiving ------------------------------------------------------------------------------

    def on_frame(self, frame: "Frame", cause: str | None, addressed: bool) -> None:
        if cause is not None or not addressed:
            return
        modem = self.modem
        if frame.kind == ACK:
            modem.consume(frame)
            if self.state == WAIT_ACK and frame.ref is self.current:
                self._done()
            return
        if frame.kind != DATA:
            return
        if self.acks and frame.dst_addr != BROADCAST and frame.dst_addr == modem.address:
            ack = modem.control_frame(ACK, self.ack_bytes, frame.src_addr, frame.src_link, frame)
            if modem.phy_busy:
                self.pending_acks.append(ack)
            else:
                modem.transmit(ack)
        if self.duplicates.seen(frame):
            modem.observer.mac(modem.clock.now(), modem, frame, "dup")
            return
        modem.deliver(frame)
