"""Built-in traffic generators: a constant interval or a Poisson process, unicast or broadcast."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .clock import Clock
    from .modem import SimModem


@dataclass(frozen=True)
class FlowSpec:
    src: str
    dst: str  # link id or "*"
    size_bytes: int
    interval_s: float  # mean gap for Poisson flows
    poisson: bool = False
    start_s: float = 0.0
    stop_s: float = float("inf")
    ack_retries: int | None = None  # the modems acknowledge each frame on the channel (acoustic_ack.py)


class FlowSource:
    """Offers ``size_bytes`` frames to ``modem`` at ``start_s``, ``start_s + interval_s``, … (computed
    as ``start_s + k·interval_s``, so no rounding error builds up), or with exponential gaps from
    ``start_s``, while before ``stop_s``."""

    def __init__(
        self,
        spec: FlowSpec,
        modem: "SimModem",
        dst_addr: int,
        clock: "Clock",
        rng: random.Random,
        stats: Any = None,
    ):
        self.spec = spec
        self.modem = modem
        self.dst_addr = dst_addr
        self.clock = clock
        self.rng = rng
        self.stats = stats
        self._count = 0
        self._handle = None

    def start(self, now: float = 0.0) -> None:
        """Begin at ``start_s``, or, when started later (a reload), at the first send after ``now``."""
        spec = self.spec
        if spec.poisson:
            first = max(spec.start_s, now) + self.rng.expovariate(1.0 / spec.interval_s)
        elif now > spec.start_s:
            self._count = math.ceil((now - spec.start_s) / spec.interval_s)
            first = spec.start_s + self._count * spec.interval_s
        else:
            first = spec.start_s
        self._schedule(first)

    def stop(self) -> None:
        if self._handle is not None:
            self.clock.cancel(self._handle)
            self._handle = None

    def _schedule(self, t: float) -> None:
        if t < self.spec.stop_s:
            self._handle = self.clock.at(t, self._fire)
        else:
            self._handle = None

    def _fire(self) -> None:
        t = self.clock.now()
        spec = self.spec
        modem = self.modem
        frame = modem.new_frame(spec.dst, self.dst_addr, spec.size_bytes, self.stats)
        frame.ack = spec.ack_retries
        modem.send(frame)
        self._count += 1
        if spec.poisson:
            self._schedule(t + self.rng.expovariate(1.0 / spec.interval_s))
        else:
            self._schedule(spec.start_s + self._count * spec.interval_s)
