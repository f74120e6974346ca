"""A link on the simulated medium, behind the same backend interface as a real modem's driver."""

from __future__ import annotations

from typing import Any, Callable

from ..core.backend import AppFrame, Backend, PhyEvent
from ..core.packets import PacketError
from ..models.frame import BROADCAST, Frame
from ..models.modem import SimModem


class SimBackend(Backend):
    """A link on the simulated medium: its :class:`SimModem` does the work."""

    kind = "sim"

    def __init__(self, modem: SimModem, link_names: Callable[[str, int], str], everyone_in_range: bool = False,
                 limits: Any = None):
        self.modem = modem
        self.sim_modem = modem  # (an attribute, not a property: the link's send reads it for every frame)
        super().__init__()
        self._link_names = link_names
        self.everyone_in_range = everyone_in_range  # see LinkSpec.everyone_in_range
        self.limits = limits  # LinkSpec.limits: what the real modem would accept (None: anything)
        self.on_phy: Callable[[PhyEvent], Any] | None = None
        modem.on_deliver = self._deliver
        modem.acks.on_outcome = self._acknowledged

    @property
    def on_idle(self) -> Callable[[], Any] | None:  # type: ignore[override]
        return self.modem.on_idle

    @on_idle.setter
    def on_idle(self, callback: Callable[[], Any] | None) -> None:
        self.modem.on_idle = callback  # the modem tells the link itself: READY follows one call sooner

    def rebind(self, modem: SimModem) -> None:
        callback, self.modem = self.modem.on_idle, modem
        self.sim_modem = modem
        modem.on_deliver = self._deliver
        modem.on_idle = callback
        modem.acks.on_outcome = self._acknowledged
        modem.on_phy = self._phy if self.on_phy is not None else None

    def watch_phy(self, listener: Callable[[PhyEvent], Any] | None) -> None:
        """Report the modem's transmissions and arrivals to ``listener`` (None: stop; nothing is then
        scheduled for it, so links without an emulated modem pay nothing)."""
        self.on_phy = listener
        self.modem.on_phy = self._phy if listener is not None else None

    def _phy(self, kind: str, frame: Frame, start: float | None, end: float, cause: str | None) -> None:
        if self.on_phy is not None:
            app = frame.app_frame if isinstance(frame.app_frame, AppFrame) else None
            self.on_phy(PhyEvent(kind, app, frame.size, frame.src_addr, frame.dst_addr, start, end, cause))

    def set_address(self, address: int) -> bool:
        self.modem.set_address(address)
        return True

    def set_band(self, band_khz: tuple[float, float]) -> bool:
        self.modem.set_band(band_khz)
        return True

    def withdraw(self, frames: list[AppFrame], cause: str) -> int:
        """Take these application frames out of the modem's FIFO if they are still queued."""
        wanted = {id(frame) for frame in frames}
        return self.modem.withdraw(lambda frame: id(frame.app_frame) in wanted, cause)

    state = "up"  # a simulated modem is always up (a class attribute: READY asks it at every change)

    @property
    def idle(self) -> bool:
        return self.modem.idle

    def admit(self, frame: AppFrame) -> None:
        """A GLI frame the real modem would refuse (its preset's ``limits:``, mode ``send_as``) is refused
        here too, with the driver's words.  An emulated modem's frames (with ``meta``) were checked by
        the emulator against their own mode."""
        limits = self.limits
        if limits is not None and frame.meta is None:
            problem = limits.refusal(len(frame.real))
            if problem is not None:
                raise PacketError("size", problem)

    def send(self, frame: AppFrame) -> bool:
        modem = self.modem
        # (an emulated EvoLogics modem's frames, with meta, carry the modem's own acoustic addresses)
        dst = BROADCAST if self.everyone_in_range and frame.meta is None else frame.dst
        dst_name = "*" if dst == BROADCAST else self._link_names(modem.tx_channel, dst)
        sim_frame = modem.new_frame(dst_name, dst, len(frame.real), app_frame=frame)
        if frame.airtime_s is not None:
            sim_frame.airtime = frame.airtime_s  # a modem with several rates (an emulated Micro-Modem)
        if frame.ack_retries is not None and dst != BROADCAST:
            sim_frame.ack = frame.ack_retries  # the modem acknowledges it on the channel (acoustic_ack.py)
        if modem.send(sim_frame):
            return True
        if sim_frame.ack is not None and frame.on_acknowledged is not None:
            frame.on_acknowledged(frame, False, None)  # dropped before the air (FIFO full): it failed now
        elif frame.on_dropped is not None:
            frame.on_dropped(frame, "fifo")
        return False

    def _acknowledged(self, frame: Frame, delivered: bool, tau: float | None) -> None:
        app_frame = frame.app_frame
        if isinstance(app_frame, AppFrame) and app_frame.on_acknowledged is not None:
            app_frame.on_acknowledged(app_frame, delivered, tau)

    def _deliver(self, frame: Frame) -> None:
        # Frames of built-in flows carry no application payload: they are background traffic.
        if isinstance(frame.app_frame, AppFrame) and self.on_receive is not None:
            frame.app_frame.pkt = frame.id
            self.on_receive(frame.app_frame)

    def status(self) -> dict[str, Any]:
        stats = self.modem.stats
        return {"tx_packets": stats.tx_packets, "rx_packets": stats.rx_packets, "drops": stats.fifo_drops,
                "fifo_bytes": self.modem.queued_bytes, "fifo_peak_bytes": stats.fifo_peak_bytes, "lost": dict(stats.lost)}

    def close(self) -> None:
        self.modem.on_deliver = None
        self.modem.on_idle = None
        self.modem.acks.on_outcome = None
        self.modem.on_phy = None
