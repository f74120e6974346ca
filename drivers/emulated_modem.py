"""What every emulated modem is (:class:`EmulatedModem`) and the hosts it serves: a pty (:mod:`.emulator_pty`)
or the clients of a TCP port (:mod:`.emulator_tcp`), as its link's ``emulate:`` says."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

from hilgate.core.endpoint import LinkPort

from .emulator_pty import PtyHost
from .emulator_tcp import TcpHosts


def open_hosts(spec: dict, scheduler: Any, on_data, on_connect, name: str, on_disconnect=None):
    """The hosts ``spec`` (a link's ``emulate:``) names: a pty, a host at once, or a TCP port's clients."""
    if "pty" in spec:
        host = PtyHost(spec["pty"], scheduler, on_data, name)
        on_connect(host)
        return host
    return TcpHosts(int(spec["tcp"]), scheduler, on_data, on_connect, name, on_disconnect=on_disconnect)


class EmulatedModem(ABC):
    """What every emulated modem is: an endpoint of kind ``emulator`` on its link's port, and the hosts its
    ``emulate:`` names (a pty, or the clients of a TCP port).  Those that speak a line protocol give each
    host a codec of its own (the modem side of the protocol, sans I/O: ``codec``), made when the host
    connects and dropped when it leaves; a subclass opens the hosts (:meth:`_serve_hosts`) once its own
    state is set, since a pty is a host at once."""

    kind = "emulator"
    assumes_busy = False  # (hilgate.core.endpoint.Endpoint.assumes_busy: an emulated modem is told BUSY by the link)
    codec: Any = None

    def __init__(self, port: LinkPort, spec: dict, scheduler: Any):
        self.port = port
        self.options = spec
        self.scheduler = scheduler

    def _serve_hosts(self) -> None:
        self.codecs: dict[Any, Any] = {}
        self.hosts = open_hosts(self.options, self.scheduler, self._on_data, self._on_connect, self.port.id,
                                 lambda host: self.codecs.pop(host, None))

    def _on_connect(self, host: Any) -> None:
        self.codecs[host] = self.codec()

    @abstractmethod
    def _on_data(self, host: Any, data: bytes) -> None:
        """``host``'s bytes (a pty or a TCP client), to its codec."""

    def _codec_of(self, host: Any) -> Any:
        """``host``'s codec (made here too: a TCP client's first bytes may come before its connect is seen)."""
        codec = self.codecs.get(host)
        if codec is None:
            codec = self.codecs[host] = self.codec()
        return codec

    def _to_hosts(self, line: bytes) -> None:
        """``line`` to every host (what a modem prints on its one serial line, to each client on TCP)."""
        for host in list(self.codecs):
            host.write(line)

    def close(self) -> None:
        self.hosts.close()

