"""``flows:``: the built-in traffic generators, each from one link to another (or ``"*"``).

A flow is checked against the links it names: both exist, and the receiver listens on the channel
the sender transmits on (else it could never hear the flow).
"""

from __future__ import annotations

import math

from ..models.flows import FlowSpec
from .checks import Fields, boolean, integer, number, text
from .specs import LinkSpec
from .yaml_nodes import Node

__all__ = ["FLOW_KEYS", "MAX_FRAME_BYTES", "flow_spec"]

FLOW_KEYS = ("from", "to", "size_bytes", "interval_s", "rate_hz", "poisson", "start_s", "stop_s", "ack_retries")
MAX_FRAME_BYTES = 1 << 20
"""The largest frame a flow may offer: 1 MiB, the largest transmit buffer of any modem hilgate knows (an
EvoLogics ``ZL``) and twice a link's default FIFO.  Without a bound ``1e300`` was a frame whose airtime
no float can hold."""


def flow_spec(node: Node, path: str, links: dict[str, LinkSpec], duration: float) -> FlowSpec:
    f = Fields(node, path, FLOW_KEYS)
    src = f.get("from", text)
    if src not in links:
        raise f.child("from").error(f.sub("from"), f"no link {src!r}; links: {', '.join(links)}")
    dst = f.get("to", text)
    if dst != "*":
        if dst not in links:
            raise f.child("to").error(f.sub("to"), f"no link {dst!r} (or \"*\" for broadcast)")
        if dst == src:
            raise f.child("to").error(f.sub("to"), "a flow cannot go to its own link")
        if links[dst].params.rx_channel != links[src].params.tx_channel:
            raise f.child("to").error(
                f.sub("to"),
                f"{dst!r} listens on channel {links[dst].params.rx_channel!r} but {src!r} transmits on "
                f"{links[src].params.tx_channel!r}: it can never hear this flow",
            )
    size = f.get("size_bytes", integer(1, MAX_FRAME_BYTES))
    if ("interval_s" in f) == ("rate_hz" in f):
        raise f.error("give exactly one of interval_s or rate_hz")
    if "interval_s" in f:
        interval = f.get("interval_s", number(above=0))
    else:
        interval = 1.0 / f.get("rate_hz", number(above=0))
    poisson = f.get("poisson", boolean, False)
    start = f.get("start_s", number(0), 0.0)
    stop = f.get("stop_s", number(0, allow_inf=True), math.inf)
    if stop <= start:
        raise f.child("stop_s").error(f.sub("stop_s"), f"must be after start_s ({start:g})")
    ack_retries = f.get("ack_retries", integer(0, 255), None)
    if ack_retries is not None and dst == "*":
        raise f.child("ack_retries").error(f.sub("ack_retries"), "a broadcast flow is not acknowledged")
    return FlowSpec(src, dst, size, interval, poisson, start, stop, ack_retries)
