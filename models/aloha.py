"""Pure ALOHA that drops a frame offered while the PHY transmits (``mac: aloha``), as ns-3's UanMacAloha.

``mac: none`` keeps such a frame in the FIFO and sends it when the PHY is free, which is what a real
modem does.  ns-3's UAN ALOHA has no queue: ``UanMacAloha::Enqueue`` refuses a packet while its PHY
is in TX.  This MAC does the same so that hilgate's ALOHA ring can match ns-3's exactly
(``benchmarks/ring_aloha.py --drop-when-busy``).  A refused frame is traced as MAC event ``drop``
with cause ``busy`` and counted in the summary's MAC events; no acknowledgement, no retry.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .mac import Mac

if TYPE_CHECKING:
    from .frame import Frame


class Aloha(Mac):
    name = "aloha"
    hears_all = False

    def on_enqueue(self) -> None:
        modem = self.modem
        while modem.fifo:
            frame = modem.fifo_pop()
            if modem.phy_busy:
                modem.observer.mac(modem.clock.now(), modem, frame, "drop", cause="busy")
                modem.check_idle()
            else:
                modem.transmit(frame)

    def on_tx_done(self, frame: "Frame") -> None:
        """Nothing waits: every frame went on air or was dropped when it was offered."""
