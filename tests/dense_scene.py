"""A dense scene for the interference tests: static modems that all hear each other, a few moving ones,
a receiver in another band, a promiscuous one, ALOHA, CS-ALOHA (carrier sense, acknowledgements) and
no MAC, unicast and broadcast flows loaded enough to collide, with ``collisions: overlap`` or ``sinr``.

Its traces were recorded by the medium that handed every arrival to every radio at once (before issue
31's lazy interference): ``dense_traces.json``."""

from __future__ import annotations

import random


def dense_scene(collisions: str, nodes: int = 24, seed: int = 7, duration_s: float = 300.0) -> str:
    """The scene text: ``nodes`` static modems on a grid 120 m apart, two moving ones, one in another
    band; every modem's error model physical with ``collisions`` (``overlap`` or ``sinr``)."""
    rng = random.Random(seed)
    lines = [f"name: dense-{collisions}", f"seed: {seed}", f"duration_s: {duration_s}",
             "channels: {ac: {speed_mps: 1500}}", "vehicles:"]
    for i in range(nodes):
        lines.append(f"  v{i}: {{pose: {{static: [{120.0 * (i % 6)}, {120.0 * (i // 6)}, 10]}}}}")
    for i, (x, y) in enumerate(((60.0, 60.0), (420.0, 300.0))):
        legs = ", ".join(f"{{to: [{x + dx}, {y + dy}, 10], speed_mps: 1.5}}" for dx, dy in ((40, 0), (40, 40), (0, 40), (0, 0)))
        lines.append(f"  w{i}: {{pose: {{path: {{start: [{x}, {y}, 10], legs: [{legs}], loop: true}}}}}}")
    lines.append("  far: {pose: {static: [300, 200, 20]}}")
    error = f"{{kind: physical, collisions: {collisions}, capture_db: 6}}"
    lines.append(f"x-m: &m {{model: evologics-s2cr-18-34, channel: ac, error: {error}}}")
    lines.append("links:")
    macs = ("none", "aloha", "cs-aloha")
    for i in range(nodes):
        extra = ", range_m: [0, 400]" if i % 7 == 3 else ""
        extra += ", promiscuous: true" if i == 5 else ""
        lines.append(f"  m{i}: {{<<: *m, vehicle: v{i}, address: {i + 1}, mac: {macs[i % 3]}{extra}}}")
    lines.append(f"  mw0: {{<<: *m, vehicle: w0, address: {nodes + 1}, mac: cs-aloha}}")
    lines.append(f"  mw1: {{<<: *m, vehicle: w1, address: {nodes + 2}}}")
    lines.append(f"  other: {{model: evologics-s2cr-7-17, channel: ac, vehicle: far, address: {nodes + 3}, "
                 f"error: {{kind: physical, collisions: {collisions}}}}}")
    lines.append("flows:")
    names = [f"m{i}" for i in range(nodes)] + ["mw0", "mw1"]
    for name in names:
        to = rng.choice([other for other in names if other != name] + ["other"])
        lines.append(f"  - {{from: {name}, to: {to}, size_bytes: {rng.choice((32, 64, 120))}, "
                     f"rate_hz: {rng.choice((0.05, 0.1, 0.2))}, poisson: true}}")
    lines.append("  - {from: m0, to: \"*\", size_bytes: 40, interval_s: 7}")
    lines.append("  - {from: mw0, to: \"*\", size_bytes: 40, interval_s: 11}")
    lines.append("  - {from: other, to: m1, size_bytes: 40, interval_s: 13}")
    return "\n".join(lines) + "\n"
