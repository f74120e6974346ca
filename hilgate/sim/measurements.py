"""What an emulated modem on a simulated link reads off the simulation: a frame's air time, the propagation
delay from another modem, the reception it measures (positions, distance, radial speed, RSSI, integrity:
:mod:`hilgate.models.link_budget`) and a USBL's fix (:mod:`hilgate.models.usbl`).

Geometry for emulators, kept apart from the link that routes frames (:class:`hilgate.daemon.routed_link.RoutedLink`
gives each link one :class:`ModemMeasurements`, its ``measure``): a real modem's link has no simulated modem,
and every answer is then None.
"""

from __future__ import annotations

import random
from typing import Any, Callable

from ..models.link_budget import Reception, SimpleLinkBudget, reception
from ..models.usbl import UsblFix, fix as usbl_fix


class ModemMeasurements:
    """One link's measurements, read from whatever simulated modem is behind it now (``modem()``: None on a
    real modem), with its USBL parameters as the scene says now (``usbl()``) and the USBL's noise drawn
    from a stream of the link's own, seeded by the scene (``seed()``) when first needed."""

    def __init__(self, link_id: str, modem: Callable[[], Any], usbl: Callable[[], Any], seed: Callable[[], int]):
        self.link_id = link_id
        self.modem = modem
        self.usbl = usbl
        self.seed = seed
        self._usbl_rng: random.Random | None = None

    def airtime(self, size: int) -> float | None:
        modem = self.modem()
        return None if modem is None else modem.airtime(size)

    def _sender(self, address: int) -> Any:
        modem = self.modem()
        if modem is None:
            return None, None
        return modem, modem.medium.modem_by_address(modem.rx_channel, address)

    def delay_from(self, address: int, t: float) -> float | None:
        mine, theirs = self._sender(address)
        # the time the frame took, whatever the range table says now (it was heard)
        return None if theirs is None else mine.medium.propagation_delay(theirs.radio, mine.radio, t, in_range=False)

    def reception_from(self, address: int, t: float) -> Reception | None:
        """What this link's modem measures of a frame from ``address`` heard at ``t``; None if unknown."""
        mine, theirs = self._sender(address)
        if theirs is None:
            return None
        return reception(theirs.pose, mine.pose, t, SimpleLinkBudget(theirs.range_m[1]))

    def usbl_fix(self, address: int, t: float) -> tuple[Reception, UsblFix] | None:
        """The link's USBL fix of the modem at ``address`` at ``t``; None when the link is no USBL or either
        position is unknown."""
        params = self.usbl()
        if params is None:
            return None
        heard = self.reception_from(address, t)
        if heard is None:
            return None
        if self._usbl_rng is None:
            self._usbl_rng = random.Random(f"{self.seed()}/{self.link_id}/usbl")
        return heard, usbl_fix(heard.receiver, heard.sender, params, self._usbl_rng)
