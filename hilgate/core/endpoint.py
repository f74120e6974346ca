"""The narrow interface between a link and the doors applications reach it through.

A *link* (one DCComms id, :class:`hilgate.daemon.router.RoutedLink`) has a backend (a simulated modem or a
real one) and endpoints in front: the dccomms POSIX queues, socket clients, an emulated modem, later
Zenoh.  The two sides know each other only through this module:

- an endpoint is handed a :class:`LinkPort`, what it may ask of the link: its id, address, packet
  class, whether it is READY, to send a frame, to count and trace a frame it lost, the COMMAND answers
  for socket clients, and, for an emulated modem, air time and propagation delays;
- the link gets back an :class:`Endpoint`: it delivers received frames to it, tells it READY/BUSY,
  and closes it.

Delivering a frame and announcing the state are then one loop over the endpoints, and the router
imports no endpoint class: the daemon gives it *doors* (:class:`Door`), factories that open a link's
endpoints when the link appears and follow its changes on a reload.
"""

from __future__ import annotations

from typing import Any, Callable, Protocol

from .backend import AppFrame, PhyEvent
from .packets import Decoded, PacketClass

TAKEN = "taken"
"""An application has the frame (in its queue, on its socket, printed by the emulated modem)."""
KEPT = "kept"
"""Nobody has shown up to read it yet; kept for an application that starts late."""
ABSENT = "absent"
"""Nobody was there to take it (and it was not kept)."""
# anything else an endpoint's deliver() returns is the cause of a loss: app_full, client_slow, size…


class LinkPort(Protocol):
    """What an endpoint may ask of its link."""

    id: str
    packet: PacketClass

    @property
    def address(self) -> int: ...

    @property
    def gli(self) -> tuple[str, ...]:
        """The GLI endpoints the scene gives the link (``mq``, ``socket``): a door opens only its own."""

    @property
    def ready(self) -> bool:
        """READY: the backend is up and idle, and no endpoint holds the link busy."""

    @property
    def emulate(self) -> dict[str, Any]:
        """The scene's ``emulate:`` options for this link (empty when it emulates no modem)."""

    @property
    def limits(self) -> Any:
        """What the link's modem accepts (``drivers.table.ModemLimits``, its ``limits:``), None if not stated."""

    @property
    def bitrate_bps(self) -> float:
        """The link's bit rate on air (its preset's ``bitrate_bps``), whatever its backend."""

    @property
    def unet(self) -> dict[str, Any]:
        """The scene's ``unet:`` options for the link's UnetStack door (empty when it has none)."""

    def address_of(self, name: str) -> int | None:
        """The address of the link called ``name``, or of the one link of the vehicle called ``name``, on
        this link's channel (None: no such one): a UnetStack application's ``host(name)``."""

    def send(self, frame: AppFrame) -> None:
        """Hand a frame to the backend; :class:`~hilgate.core.packets.PacketError` if it cannot carry it."""

    def send_payload(self, payload: bytes, dst: int) -> None:
        """Wrap ``payload`` in the link's packet class and send it (a socket client's SEND)."""

    def send_decoded(self, decoded: Decoded, sender: Any = None) -> None:
        """Send a frame a dccomms application wrote (real packet and virtual area, decoded); ``sender``: the
        endpoint it came through, when its applications take the link as BUSY once they send
        (:attr:`Endpoint.assumes_busy`)."""

    def lost(self, cause: str, size: int, src: str = "medium", n: int = 1, **fields: Any) -> None:
        """A frame this endpoint could not take or pass on (``n`` alike): counted by cause and traced
        (``fields``: what else the trace line says of it)."""

    def state_changed(self) -> None:
        """Something that READY depends on changed (an emulated modem's pending acknowledgement)."""

    def command(self, request: Any) -> dict[str, Any]:
        """A socket client's request about the link or its vehicle (STATUS, POSE, GOTO…)."""

    def attach(self, endpoint: "Endpoint") -> bool:
        """Deliver to ``endpoint`` from now on; False when the link has as many clients as it may."""

    def detach(self, endpoint: "Endpoint") -> None: ...

    def airtime(self, size: int) -> float | None:
        """Model seconds a frame of ``size`` bytes is on air (None when a real modem carries the link)."""

    def delay_from(self, address: int, t: float) -> float | None:
        """Propagation delay from the modem at ``address`` to this link's, as an arrival between them
        now would take (None: unknown, or either position is)."""

    def reception_from(self, address: int, t: float) -> Any:
        """The receiving modem's measurements of a frame from ``address`` (a ``models.link_budget.Reception``)."""

    def usbl_fix(self, address: int, t: float) -> Any:
        """``(Reception, UsblFix)`` of the modem at ``address`` when the link is a USBL, else None."""

    def set_address(self, address: int) -> None:
        """Answer to ``address`` in the simulation from now on (an emulated modem's ``AT!AL``)."""

    def set_band(self, band_khz: tuple[float, float]) -> None:
        """Send and listen in ``band_khz`` in the simulation from now on (an emulated M64's channel)."""

    def withdraw(self, frames: list[AppFrame], cause: str) -> int:
        """Take frames sent earlier back out of the backend's queue (``ATZ``); how many were still there."""


class Endpoint(Protocol):
    """A way in and out of a link for applications."""

    kind: str
    busy: bool
    """True while this endpoint holds the link BUSY (an emulated modem awaiting an acknowledgement)."""
    assumes_busy: bool
    """An optional capability (False in an endpoint without it): this endpoint's applications take the link as BUSY once
    they send a frame, and the endpoint knows it was told so (dccomms' WritePacket; the queue protocol
    notes it as it reads the frame).  When such an endpoint is the link's only one, the link need not
    announce BUSY after that endpoint's frame while its modem is on air: nobody would be told anything
    (issue 31, :meth:`hilgate.daemon.router.RoutedLink.send`)."""
    phy: Callable[[PhyEvent], Any] | None
    """An optional capability: where the link reports its simulated modem's transmissions and arrivals
    (an emulated modem's extended notifications); None for an endpoint that does not want them, and
    then the link's backend reports nothing (nothing is scheduled for it)."""

    def deliver(self, frame: AppFrame, t: float) -> str:
        """Give an application a frame the link received; :data:`TAKEN`, :data:`KEPT`, :data:`ABSENT`
        or the cause of a loss."""

    def state(self, ready: bool) -> None:
        """The link's READY/BUSY (the endpoint says it only when it changed for its applications)."""

    def close(self) -> None: ...


class Door(Protocol):
    """Opens a link's endpoints of one kind when the link appears (``open``), follows a reload
    (``update``: the packet class or the emulator's options may have changed) and closes them."""

    def open(self, port: LinkPort) -> Any:
        """Whatever must be kept to follow and close this link's endpoints (None: nothing opened)."""

    def update(self, handle: Any, port: LinkPort) -> Any:
        """The link's spec changed: return the (possibly new) handle."""

    def close(self, handle: Any) -> None: ...
