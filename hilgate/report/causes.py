"""The words and colour of each loss cause, one table for every place a person reads a cause: the
report's figures and tables, ``hilgate sim``'s printed table, and the web view's page (which gets it in
its SCENE message).  Two tables would drift apart, and a journal's reader cannot be expected to know
that ``mult`` is a collision with errors.

The trace keeps its short codes: scripts match on them, and they are documented in docs/reports.md.
A code this table does not know (a newer daemon's, a hand-made trace's) reads "other (code)", in the
one colour kept for the unknown.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

log = logging.getLogger(__name__)

__all__ = ["Cause", "CAUSES", "RECEIVED", "OTHER_COLOUR", "words", "colour", "legend_order"]


@dataclass(frozen=True)
class Cause:
    words: str
    colour: str


RECEIVED = Cause("received", "#2ca02c")
"""What a frame that was not lost is called, beside the causes (legends, the page's fates)."""

OTHER_COLOUR = "#8c564b"

_GREY = "#7f7f7f"

# In the order legends list them: the channel's own losses first (as docs/channel-models.md judges a
# frame), then the modem's and the link's, then the applications' side and the network of hosts.
CAUSES: dict[str, Cause] = {
    # the channel at a receiver
    "prop": Cause("channel errors", "#e69f00"),
    "col": Cause("collision", "#d62728"),
    "mult": Cause("collision + errors", "#9467bd"),
    "range": Cause("out of range", "#1f77b4"),
    "band": Cause("outside the band", "#17becf"),
    "modulation": Cause("modulation not decoded", "#bcbd22"),
    "no_pose": Cause("position unknown", _GREY),
    # the sending modem and its link
    "fifo": Cause("FIFO full", "#222222"),
    "busy": Cause("modem busy sending", "#e377c2"),
    "closed": Cause("link closed", _GREY),
    "down": Cause("link down", _GREY),
    "queue_full": Cause("modem queue full", OTHER_COLOUR),
    "buffer_full": Cause("modem buffer full", OTHER_COLOUR),
    "overflow": Cause("modem input overflow", OTHER_COLOUR),
    "flushed": Cause("flushed by the modem", OTHER_COLOUR),
    "cleared": Cause("cleared by a modem reset", OTHER_COLOUR),
    "no_remote_address": Cause("no remote address set", OTHER_COLOUR),
    "refused": Cause("refused by the modem", OTHER_COLOUR),
    "failed": Cause("delivery failed", OTHER_COLOUR),
    "no_report": Cause("no report from the modem", OTHER_COLOUR),
    "data_timeout": Cause("modem data timeout", OTHER_COLOUR),
    "no_ack": Cause("no acknowledgement", OTHER_COLOUR),
    "crc": Cause("bad checksum", OTHER_COLOUR),
    "bad_crc": Cause("bad checksum", OTHER_COLOUR),
    "cobs": Cause("bad framing", OTHER_COLOUR),
    "overlong": Cause("datagram missing a packet", OTHER_COLOUR),
    "no_receiver": Cause("no modem at the address", OTHER_COLOUR),
    "no_backend": Cause("link without a modem", OTHER_COLOUR),
    # the applications' side of a link
    "no_reader": Cause("no application reading", OTHER_COLOUR),
    "app_full": Cause("application's receive queue full", OTHER_COLOUR),
    "client_slow": Cause("application too slow", OTHER_COLOUR),
    "client_queue": Cause("application's send queue full", OTHER_COLOUR),
    "not_a_frame": Cause("not a frame of the link", OTHER_COLOUR),
    "bad_frame": Cause("not a frame of the link", OTHER_COLOUR),
    "size": Cause("too long for the link", OTHER_COLOUR),
    "stale": Cause("left while no daemon ran", OTHER_COLOUR),
    "rate": Cause("application over its rate", OTHER_COLOUR),
    "clients": Cause("too many applications", OTHER_COLOUR),
    "bad_client": Cause("application refused", OTHER_COLOUR),
    # a network of hosts
    "host_down": Cause("receiver's host down", _GREY),
    "net_gap": Cause("messages missing from a host", OTHER_COLOUR),
    "replay": Cause("message replayed", OTHER_COLOUR),
    "bad_message": Cause("bad message from a host", OTHER_COLOUR),
    "damaged": Cause("damaged message from a host", OTHER_COLOUR),
}

_RANK = {code: i for i, code in enumerate(CAUSES)}
_warned: set[str] = set()


def words(code: str | None) -> str:
    """A cause in words; a frame lost with no cause traced is "cause not traced"."""
    if code is None:
        return "cause not traced"
    cause = CAUSES.get(code)
    if cause is not None:
        return cause.words
    if code not in _warned and len(_warned) < 32:  # (a hostile trace may hold thousands of made-up causes)
        _warned.add(code)
        log.debug("loss cause %r has no words in hilgate.report.causes: shown as 'other'", code)
    return f"other ({code})"


def colour(code: str | None) -> str:
    cause = CAUSES.get(code) if code is not None else None
    return cause.colour if cause is not None else OTHER_COLOUR


def legend_order(code: str | None) -> tuple[int, str]:
    """Sort key: the table's order (the channel's losses first), then unknown codes by name."""
    rank = _RANK.get(code) if code is not None else None
    return (rank, "") if rank is not None else (len(_RANK), code or "")
