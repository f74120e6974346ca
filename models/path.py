"""How one (sender, receiver) path is judged: the receiver's error model bound to the sender's
transmit side, once per pair, never per frame.

A frame's fate on a path depends on both ends, whatever error model each uses for its own traffic:
the sender gives what is on air (its ``acoustic:`` front end: source level and ``AT!L`` step, band,
modulation, coding; its bit rate), the receiver what it makes of it (its band, the modulations it
decodes, and its ``error:``).  :func:`bind_path` decides, for one pair:

1. Where both ends declare a front end, whether the receiver takes the sender's frames at all: bands
   that do not overlap → it hears nothing of them (``band``: no arrival, no interference; a frame
   addressed to it is traced ``err`` with that cause when sent, as ``range`` is); a modulation it does
   not decode → the frames arrive, keep the channel busy and interfere as any other, but one it judges
   ends lost (``modulation``).
2. The loss model: a physical receiver's model bound to the sender's front end and bit rate
   (:meth:`~.physical.PhysicalErrorModel.path_from`; a sender with no front end gets the receiver's
   own in its place), an expression receiver's expression as it is.

The medium asks once per pair when it lists its neighbours (``medium.py``), ``hilgate check`` once per
row; an arrival then costs what it cost before.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

from .physical import BAND, Acoustic, PhysicalErrorModel

if TYPE_CHECKING:
    from .radio import LossModel

__all__ = ["PathEnd", "BoundPath", "Undecodable", "bind_path", "front_of"]


class PathEnd(Protocol):
    """One end of a path: a radio (as the medium sees it) or a link's ``ModemParams`` (as ``hilgate
    check`` sees it)."""

    acoustic: Acoustic | None
    bitrate_bps: float
    error: Any


class BoundPath(NamedTuple):
    model: "LossModel"
    refused: str | None  # why the receiver takes none of the sender's frames (a trace cause), or None
    interferes: bool     # a refused sender's frames still arrive as interference (False: unheard)


class Undecodable:
    """The loss model of a path the receiver hears but cannot decode: every frame is lost (PER 1, so
    nothing is drawn), while its received power still counts as interference (``collisions: sinr``)."""

    __slots__ = ("inner", "constant_zero")

    def __init__(self, inner: Any):
        self.inner = inner
        self.constant_zero = False

    def per(self, d: float, size: int) -> float:
        return 1.0

    def per_sinr(self, d: float, size: int, interference: float) -> float:
        return 1.0

    def rx_power(self, d: float) -> float:
        return self.inner.rx_power(d)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Undecodable) and other.inner == self.inner

    def __hash__(self) -> int:
        return hash(("undecodable", self.inner))

    def __repr__(self) -> str:
        return f"Undecodable({self.inner!r})"


class Unheard(Undecodable):
    """The loss model of a path outside the receiver's band: nothing arrives, nothing interferes."""

    __slots__ = ()

    def rx_power(self, d: float) -> float:
        return 0.0


def front_of(end: PathEnd) -> Acoustic | None:
    """The end's acoustic front end: its own ``acoustic``, else its physical model's."""
    if end.acoustic is not None:
        return end.acoustic
    error = end.error
    return error.acoustic if isinstance(error, PhysicalErrorModel) else None


def bind_path(sender: PathEnd, receiver: PathEnd) -> BoundPath:
    """The model of the path from ``sender`` to ``receiver`` and whether the receiver refuses it (the
    module's doc)."""
    tx, rx = front_of(sender), front_of(receiver)
    error = receiver.error
    refused = rx.refuses(tx) if tx is not None and rx is not None else None
    if refused == BAND:
        return BoundPath(Unheard(error), BAND, False)
    if isinstance(error, PhysicalErrorModel):
        model = error.path_from(tx, sender.bitrate_bps)
    else:
        model = error
    if refused is not None:
        return BoundPath(Undecodable(model), refused, True)
    return BoundPath(model, None, True)
