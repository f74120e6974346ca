"""What the backends of the real modems (EvoLogics, S100, Modem-M64, Micro-Modem) share: the constructor
the backend table calls (``table.open_backend``) and the modem's port.

A backend keeps its link's address, packet class and options, and opens its port (:class:`.port.Port`: the
device or URL of ``port:`` at ``baud``, reopened after an outage) once its own state is set, since the
modem's first bytes may come at once; closing it closes the port before the queue.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Any, Callable

from hilgate.core.backend import QueuedBackend
from hilgate.core.packets import PacketClass

from .port import Port


class ModemBackend(QueuedBackend):
    """A real modem's backend: a subclass reads the modem's bytes in ``_on_data`` and is told in ``_on_port``
    when the port is up or down."""

    def __init__(self, link_id: str, address: int, packet: PacketClass, options: Any, scheduler: Any,
                 trace: Callable[[dict], Any]):
        super().__init__(link_id, scheduler, trace, options.queue_frames)
        self.address = address
        self.packet = packet
        self.options = options

    def _open_port(self, **line: Any) -> None:
        """Open the modem's port (``line``: more of pyserial's settings, such as ``rtscts``)."""
        self.port = Port(self.options.port, self.scheduler, self._on_data, self._on_port, baud=self.options.baud,
                         name=self.link_id, **line)
        self.port.open()

    @abstractmethod
    def _on_data(self, data: bytes) -> None:
        """The modem's bytes, as the port read them."""

    @abstractmethod
    def _on_port(self, up: bool, reason: str | None) -> None:
        """The port came up, or went down (``reason``)."""

    def close(self) -> None:
        self.port.close()
        super().close()
