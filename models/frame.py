"""What travels through the simulated stack: one frame on its way from a sender's FIFO to the air."""

from __future__ import annotations

from typing import Any

BROADCAST = 255
"""The broadcast address, as DataLinkFrame and the EvoLogics modems use it."""

DATA = "data"
ACK, RTS, CTS = "ack", "rts", "cts"


class Frame:
    """A frame of ``size`` bytes on air.

    ``src``/``dst`` are link ids for the trace (``dst`` is ``"*"`` for broadcast); ``dst_addr`` is the
    MAC address receivers match against.  ``flow`` points at the statistics of the flow that offered
    it (None for frames from applications) so that counting an event is one attribute access.
    ``app_frame`` carries the application's frame (the GLI's ``AppFrame``) for frames from applications.  MAC protocols make their
    own control frames with another ``kind`` and may hang the data frame they serve on ``ref``.
    Frames are made by the sending modem, :meth:`SimModem.new_frame`, which hands out the ids.
    """

    __slots__ = ("id", "src_link", "dst_link", "dst_addr", "size", "t0", "flow", "app_frame", "kind", "ref", "seq",
                 "src_addr", "ack", "airtime")

    def __init__(
        self,
        id: int,
        src_link: str,
        dst_link: str,
        dst_addr: int,
        size: int,
        t0: float,
        flow: Any = None,
        app_frame: Any = None,
        kind: str = DATA,
        ref: "Frame | None" = None,
        seq: int = 0,
    ):
        self.id = id
        self.src_link = src_link
        self.dst_link = dst_link
        self.dst_addr = dst_addr
        self.size = size
        self.t0 = t0
        self.flow = flow
        self.app_frame = app_frame
        self.kind = kind
        self.ref = ref
        self.seq = seq
        self.src_addr = -1  # set by the sending modem
        self.ack: int | None = None  # retries allowed when the modem acknowledges it (acoustic_ack.py)
        self.airtime: float | None = None  # seconds on air when its modem says so (a rate of its own), else size / bitrate

    def __repr__(self) -> str:
        return f"Frame(#{self.id} {self.kind} {self.src_link}->{self.dst_link} {self.size}B)"
