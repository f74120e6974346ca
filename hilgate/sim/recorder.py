"""The trace (JSON lines) and the metrics of flows, fed by the models' observer calls.

One object does both because both look at the same events: counting a flow's event is a couple of
attribute increments on the :class:`FlowStats` the frame points at, and a trace line is written only
when a trace file was asked for.  Lines are formatted by hand (link ids are JSON-encoded once) since
``json.dumps`` per event would dominate a long run.  Field order and meaning are DESIGN.md's.
"""

from __future__ import annotations

import json
import math
from array import array
from typing import Any, Iterable, TextIO

from ..models.flows import FlowSpec
from ..models.frame import BROADCAST, DATA

LOSS_CAUSES = ("prop", "col", "mult", "range")
"""Counted for every flow; other causes (``band``, ``modulation``: a receiver that refuses the sender)
are added to a flow's ``lost`` when they happen."""


class FlowStats:
    """What happened to one configured flow. Receptions and losses count per receiver (a broadcast
    heard by three vehicles counts three), and jitter is taken along each receiver's own sequence."""

    __slots__ = ("spec", "offered", "fifo_drops", "tx_packets", "tx_bytes", "rx_packets", "rx_bytes", "lost",
                 "delays", "_last_delay", "_jitter_sum", "_jitter_n")

    def __init__(self, spec: FlowSpec):
        self.spec = spec
        self.offered = 0
        self.fifo_drops = 0
        self.tx_packets = 0
        self.tx_bytes = 0
        self.rx_packets = 0
        self.rx_bytes = 0
        self.lost = dict.fromkeys(LOSS_CAUSES, 0)
        self.delays = array("d")
        self._last_delay: dict[str, float] = {}
        self._jitter_sum = 0.0
        self._jitter_n = 0

    def received(self, receiver: str, delay: float, size: int) -> None:
        self.rx_packets += 1
        self.rx_bytes += size
        self.delays.append(delay)
        last = self._last_delay.get(receiver)
        if last is not None:
            self._jitter_sum += abs(delay - last)
            self._jitter_n += 1
        self._last_delay[receiver] = delay

    def summary(self, sim_time: float) -> dict[str, Any]:
        spec = self.spec
        active = min(spec.stop_s, sim_time) - spec.start_s
        delays = sorted(self.delays)
        return {
            "from": spec.src,
            "to": spec.dst,
            "offered": self.offered,
            "fifo_drops": self.fifo_drops,
            "tx_packets": self.tx_packets,
            "tx_bytes": self.tx_bytes,
            "rx_packets": self.rx_packets,
            "rx_bytes": self.rx_bytes,
            "lost": dict(self.lost),
            "throughput_Bps": _num(self.rx_bytes / active) if active > 0 else 0.0,
            "efficiency": _num(self.rx_bytes / self.tx_bytes) if self.tx_bytes else 0.0,
            "delay_mean_s": _num(math.fsum(delays) / len(delays)) if delays else None,
            "delay_p50_s": _num(percentile(delays, 0.50)) if delays else None,
            "delay_p95_s": _num(percentile(delays, 0.95)) if delays else None,
            "jitter_s": _num(self._jitter_sum / self._jitter_n) if self._jitter_n else None,
        }


def _lateness(frame: Any) -> str:
    """``, "lateness_s": x`` for a frame from an application that the daemon read late (its stamp
    ``t`` may be up to x after the application sent it); nothing otherwise."""
    payload = frame.app_frame
    late = payload.lateness if payload is not None else 0.0  # (an AppFrame: only applications' frames carry one)
    return f', "lateness_s": {round(late, 6)!r}' if late else ""


def _num(value: float) -> float:
    return round(value, 9)


def percentile(ordered: list[float], q: float) -> float:
    """Linear interpolation between closest ranks (numpy's default), on already sorted data."""
    if len(ordered) == 1:
        return ordered[0]
    position = q * (len(ordered) - 1)
    low = int(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (position - low)


class Recorder:
    """Implements the models' Observer: counts flow events and writes the trace."""

    def __init__(self, trace: TextIO | None = None, flush_each: bool = False):
        self.trace = trace
        self._write = trace.write if trace is not None else None
        self._flush = trace.flush if (trace is not None and flush_each) else None
        self._json: dict[str, str] = {}
        self.flows: list[FlowStats] = []
        self.mac_events: dict[str, int] = {}
        self.tap: Any = None
        """Who else watches the events while someone does (the daemon's web view, :mod:`hilgate.daemon.webfeed`):
        ``tap.frame(ev, t, link_id, frame, cause)`` for the modems' events, ``tap.line(record)`` for the
        free-form lines.  None (the rule): one attribute test per event."""

    def add_flow(self, spec: FlowSpec) -> FlowStats:
        stats = FlowStats(spec)
        self.flows.append(stats)
        return stats

    def close(self) -> None:
        if self.trace is not None:
            self.trace.flush()

    # -- trace lines ---------------------------------------------------------------------------

    def _name(self, name: str) -> str:
        encoded = self._json.get(name)
        if encoded is None:
            encoded = json.dumps(name)
            if len(self._json) < 65536:  # (names come from the scene, and checked ones from other hosts)
                self._json[name] = encoded
        return encoded

    def _line(self, t: float, ev: str, modem: Any, frame: Any, cause: str | None = None, extra: str = "") -> None:
        name = self._name
        line = (f'{{"t": {round(t, 9)!r}, "ev": "{ev}", "link": {modem.json_id}, "pkt": {frame.id}, '
                f'"src": {name(frame.src_link)}, "dst": {name(frame.dst_link)}, "size": {frame.size}')
        if frame.kind != DATA:
            line += f', "kind": {name(frame.kind)}'
        if cause is not None:
            line += f', "cause": "{cause}"'
        self._write(f'{line}{extra}, "fifo_bytes": {modem.queued_bytes}}}\n')
        if self._flush is not None:
            self._flush()

    def event(self, record: dict[str, Any]) -> None:
        """A free-form trace line (drivers and the GLI use it for what is not a modem event)."""
        if self.tap is not None:
            self.tap.line(record)
        if self._write is not None:
            try:
                line = json.dumps(record, allow_nan=False, default=str)
            except ValueError:  # a NaN or infinity: not JSON; written as text
                line = json.dumps({k: (v if not isinstance(v, float) or math.isfinite(v) else str(v))
                                   for k, v in record.items()}, default=str)
            self._write(line + "\n")
            if self._flush is not None:
                self._flush()

    # -- Observer ------------------------------------------------------------------------------

    def enq(self, t: float, modem: Any, frame: Any) -> None:
        stats = frame.flow
        if stats is not None and frame.kind == DATA:
            stats.offered += 1
        if self.tap is not None:
            self.tap.frame("enq", t, modem.id, frame, None)
        if self._write is not None:
            self._line(t, "enq", modem, frame, None, _lateness(frame))

    def drop(self, t: float, modem: Any, frame: Any, cause: str) -> None:
        stats = frame.flow
        if stats is not None and frame.kind == DATA:
            stats.offered += 1
            if cause == "fifo":
                stats.fifo_drops += 1
        if self.tap is not None:
            self.tap.frame("drop", t, modem.id, frame, cause)
        if self._write is not None:
            self._line(t, "drop", modem, frame, cause, _lateness(frame))

    def tx(self, t: float, modem: Any, frame: Any) -> None:
        stats = frame.flow
        if stats is not None:
            stats.tx_bytes += frame.size
            if frame.kind == DATA:
                stats.tx_packets += 1
        if self.tap is not None:
            self.tap.frame("tx", t, modem.id, frame, None)
        if self._write is not None:
            self._line(t, "tx", modem, frame)

    def rx(self, t: float, modem: Any, frame: Any) -> None:
        stats = frame.flow
        if stats is not None and frame.kind == DATA and (
            frame.dst_addr == modem.address or frame.dst_addr == BROADCAST
        ):
            stats.received(modem.id, t - frame.t0, frame.size)
        if self.tap is not None:
            self.tap.frame("rx", t, modem.id, frame, None)
        if self._write is not None:
            self._line(t, "rx", modem, frame)

    def err(self, t: float, modem: Any, frame: Any, cause: str) -> None:
        stats = frame.flow
        if stats is not None and frame.kind == DATA and (
            frame.dst_addr == modem.address or frame.dst_addr == BROADCAST
        ):
            stats.lost[cause] = stats.lost.get(cause, 0) + 1  # (no_pose, closed, band, modulation… beside the usual four)
        if self.tap is not None:
            self.tap.frame("err", t, modem.id, frame, cause)
        if self._write is not None:
            self._line(t, "err", modem, frame, cause)

    def mac(self, t: float, modem: Any, frame: Any, ev: str, **fields: Any) -> None:
        self.mac_events[ev] = self.mac_events.get(ev, 0) + 1
        if self._write is not None:
            cause = fields.pop("cause", None)
            extra = "".join(f", {json.dumps(k)}: {json.dumps(v)}" for k, v in fields.items())
            self._line(t, ev, modem, frame, cause, extra)

    # -- summary -------------------------------------------------------------------------------

    def summary(self, scene: Any, seed: int, sim_time: float, wall_time: float,
                modems: Iterable[Any] = (), links: list[dict[str, Any]] | None = None) -> dict[str, Any]:
        """DESIGN.md's summary.  ``links``: the daemon's accounts (every link it served, with one segment
        per backend period); else one entry per simulated modem, simulated for the whole run."""
        return {
            "scene": scene.name,
            "seed": seed,
            "sim_time_s": _num(sim_time),
            "wall_time_s": round(wall_time, 4),
            "flows": [stats.summary(sim_time) for stats in self.flows],
            "links": links if links is not None else [_modem_entry(modem, sim_time) for modem in modems],
        }


def _modem_entry(modem: Any, sim_time: float) -> dict[str, Any]:
    """A simulated modem's line of the summary: its totals, and the one backend period it had (the
    daemon's summary has a period per backend a link had)."""
    stats = modem.stats
    return {
        "id": modem.id,
        "tx_packets": stats.tx_packets,
        "rx_packets": stats.rx_packets,
        "fifo_drops": stats.fifo_drops,
        "fifo_peak_bytes": stats.fifo_peak_bytes,
        "backend": "sim",
        "segments": [{"backend": "sim", "start_s": 0.0, "end_s": _num(sim_time), "tx_packets": stats.tx_packets,
                      "rx_packets": stats.rx_packets, "drops": stats.fifo_drops,
                      "fifo_peak_bytes": stats.fifo_peak_bytes}],
    }
