"""A link as ``hilgate status`` shows it: totals over every backend it has had in the run, what its applications
lost and what nobody was there to read, READY, whom an application's frame reaches, since when it has its
backend."""

from __future__ import annotations

from typing import Any

UNREAD_CAUSES = ("no_reader",)


def link_status(link: Any) -> dict[str, Any]:
    """``link``'s status (a :class:`~hilgate.daemon.routed_link.RoutedLink`)."""
    backend = link.backend
    figures = backend.status() if backend else {"fifo_bytes": 0}
    totals = link.account.totals()  # over every backend the link has had in this run
    causes = totals["drop_causes"]
    current = link.account.current
    status = {
        "id": link.id,
        "backend": link.spec.backend,
        "state": backend.state if backend else "down",
        "tx_packets": totals["tx_packets"],
        "rx_packets": totals["rx_packets"],
        # what an application lost; a frame no application was there to read is counted apart
        "drops": totals["drops"] + sum(n for cause, n in causes.items() if cause not in UNREAD_CAUSES),
        "fifo_bytes": figures["fifo_bytes"],
        "unread": causes.get("no_reader", 0) + totals["unread_kept"],
        "drop_causes": causes,
        "clients": link.clients,
        # what the link's applications are told (READY/BUSY): false while a frame is still in the
        # modem's hands, e.g. a real modem's IM until its DELIVEREDIM or FAILEDIM
        "ready": link.ready,
        # whom a frame from an application reaches: its destination, or everyone in range where the
        # packet class carries no address on air and no MAC needs one (addressing: auto)
        "app_dst": "everyone in range" if backend is not None and backend.everyone_in_range else "as addressed",
        # since when the link has had this backend: model time, and the wall clock (UTC)
        "since_s": round(current.start, 6) if current is not None else None,
        "since": current.since if current is not None else None,
    }
    if figures.get("reason"):
        status["reason"] = figures["reason"]
    return status
