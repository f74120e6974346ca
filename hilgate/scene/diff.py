"""What a reload changed, decided in one place: the daemon's world, router and live sources apply it.

A reload must change only what differs (a link whose FIFO is full keeps it, an application's socket
stays connected), and every part must agree on what "differs" means.  :func:`diff` compares two
validated scenes and says, per link and per vehicle, what was added, removed or changed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from . import LinkSpec, Scene  # the package re-exports the specs, wherever they live


@dataclass(frozen=True)
class LinkChange:
    """One link id that is new, gone, or different (``before``/``after`` None when added/removed)."""

    id: str
    before: LinkSpec | None
    after: LinkSpec | None

    @property
    def removed(self) -> bool:
        return self.after is None

    @property
    def backend_changed(self) -> bool:
        """Another kind of backend, or a real modem's options (port, baud…, its limits): a new backend is
        opened."""
        b, a = self.before, self.after
        return b is not None and a is not None and (
            b.backend != a.backend or (a.backend != "sim" and (b.options != a.options or b.limits != a.limits)))

    @property
    def modem_changed(self) -> bool:
        """The simulated modem's parameters (bitrate, delays, FIFO, range, error model…)."""
        return self.before is not None and self.after is not None and self.before.params != self.after.params

    @property
    def mac_changed(self) -> bool:
        return self.before is not None and self.after is not None and self.before.mac != self.after.mac

    @property
    def endpoints_changed(self) -> bool:
        """What the doors in front of the link look at: its packet class, its emulated modem or its GLI
        endpoints."""
        b, a = self.before, self.after
        return b is not None and a is not None and (b.packet != a.packet or b.emulate != a.emulate
                                                    or b.gli != a.gli or b.unet != a.unet)


@dataclass(frozen=True)
class SceneDiff:
    links: dict[str, LinkChange] = field(default_factory=dict)
    vehicles: frozenset[str] = frozenset()          # added or changed: their pose sources are rebuilt
    vehicles_removed: frozenset[str] = frozenset()
    channels_changed: bool = False
    flows_changed: bool = False

    @property
    def empty(self) -> bool:
        return not (self.links or self.vehicles or self.vehicles_removed or self.channels_changed
                    or self.flows_changed)


def diff(before: Scene | None, after: Scene) -> SceneDiff:
    """Everything in ``after`` that is not as in ``before`` (everything, when there was no scene)."""
    old_links = before.links if before is not None else {}
    links = {}
    for link_id in old_links.keys() | after.links.keys():
        b, a = old_links.get(link_id), after.links.get(link_id)
        if b != a or (b is not None and a is not None and b.emulate != a.emulate):
            links[link_id] = LinkChange(link_id, b, a)
    old_vehicles = before.vehicles if before is not None else {}
    changed = frozenset(name for name, vehicle in after.vehicles.items() if old_vehicles.get(name) != vehicle)
    removed = frozenset(name for name in old_vehicles if name not in after.vehicles)
    return SceneDiff(
        links=links,
        vehicles=changed,
        vehicles_removed=removed,
        channels_changed=before is None or before.channels != after.channels,
        flows_changed=before is None or before.flows != after.flows,
    )
