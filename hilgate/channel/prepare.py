"""A scene's channels with water, made ready: the frequencies its modems use, their fields (cached, or
computed by BELLHOP with a progress bar), and the :class:`~hilgate.models.bellhop_fields.BellhopChannel`
each such channel gives its paths through.  ``hilgate channel prepare SCENE`` does it ahead of time; a
world does it when it is built (then from the cache, in a moment)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, Mapping

from ..models.medium import Channel
from ..models.path import front_of
from ..models.propagations import PROPAGATIONS

if TYPE_CHECKING:
    from .runner import Program, Progress

# BELLHOP's fields and their runner (numpy: 15 MB of a process) are imported when a channel has water,
# not by every simulation: a dense ring of 250 modems fits in what numpy alone would take.

__all__ = ["frequencies_of", "ready_channels"]


def frequencies_of(channel: Channel, links: Mapping[str, Any]) -> set[float]:
    """The frequencies (Hz) the paths of ``channel`` are looked up at: one per distinct pair of
    front ends between its senders and its receivers (the water's ``frequency_khz`` for a pair
    without any, and for a channel without pairs)."""
    water = channel.water
    senders = {front_of(link.params) for link in links.values() if link.params.tx_channel == channel.name}
    receivers = {front_of(link.params) for link in links.values() if link.params.rx_channel == channel.name}
    default = water.frequency_khz * 1000.0
    from ..models.bellhop_fields import path_frequency_hz
    return {path_frequency_hz(tx, rx, default) for tx in senders for rx in receivers} or {default}


def ready_channels(channels: Mapping[str, Channel], links: Mapping[str, Any], *, program: Program | None = None,
                   cache: str | None = None, progress: Progress | None = None) -> dict[str, Channel]:
    """``channels`` with every channel whose model is traced (``propagation: bellhop``, the default with
    ``water:``) given its :class:`BellhopChannel` (its ``propagation``); the others as they are.  Raises :class:`~hilgate.channel.runner.BellhopError` when BELLHOP must
    run and cannot."""
    ready: dict[str, Channel] = {}
    for name, channel in channels.items():
        if not PROPAGATIONS[channel.model].traced:
            ready[name] = channel
            continue
        if channel.propagation.positional:  # (ready already)
            ready[name] = channel
            continue
        from ..models.bellhop_fields import BellhopChannel
        from .runner import prepare_fields

        fields = prepare_fields(channel.water, sorted(frequencies_of(channel, links)), program=program, cache=cache,
                                progress=progress)
        ready[name] = dataclasses.replace(channel, propagation=BellhopChannel(channel.water, fields,
                                                                              channel.min_delay_s))
    return ready
