"""``hilgate report TRACE --out DIR --water SCENE``: each water channel's transmission-loss field with the
vehicles' tracks over it.  Above the rooms, with the commands: it joins the trace (``report``), the scene
(``scene``) and BELLHOP's fields (``channel``).

The field is drawn from the first simulated link's vehicle on the channel (the source, at its depth at
the trace's first pose), over range from it and depth; every vehicle's track is drawn in the same
plane: its horizontal distance from the source's vehicle at each pose sample, and its depth."""

from __future__ import annotations

import math
import os

import numpy as np

__all__ = ["water_figures"]


def water_figures(trace_path: str, scene_path: str, out: str, formats: tuple[str, ...] = ("png",),
                  dpi: float = 300.0) -> list[str]:
    """The figures written (one per channel with water, each format); [] when the scene has none.  PNGs at
    ``dpi``, as ``hilgate report``'s other figures."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..channel.prepare import ready_channels
    from ..report.tracedata import load_trace
    from ..scene.load import load_scene

    scene = load_scene(scene_path)
    if not any(c.water is not None for c in scene.channels.values()):
        return []
    channels = ready_channels(scene.channels, scene.links)
    trace = load_trace(trace_path)
    written = []
    for name, channel in channels.items():
        if not channel.propagation.positional:
            continue
        senders = [l for l in scene.links.values() if l.backend == "sim" and l.params.tx_channel == name]
        if not senders:
            continue
        source = senders[0]
        track = [(t, p) for t, p in trace.poses.get(source.vehicle, []) if p is not None]
        if not track:
            continue
        water = channel.water
        fields = channel.propagation.for_frequency(channel.propagation.frequency_of(source.params, source.params))
        zs = track[0][1][2] - water.surface_z_m
        ranges = np.linspace(water.range_m / 200.0, water.range_m, 200)
        depths = np.linspace(0.0, water.deepest_m, 100)
        tl = np.array([[fields.tl_db(r, zs, z) for r in ranges] for z in depths])
        fig, ax = plt.subplots(figsize=(9, 4.5))
        mesh = ax.pcolormesh(ranges, depths, tl, shading="auto", cmap="viridis_r",
                             vmin=float(np.percentile(tl, 2)), vmax=float(np.percentile(tl, 98)))
        fig.colorbar(mesh, ax=ax, label="transmission loss (dB)")
        _draw_tracks(ax, trace.poses, source.vehicle, track, water.surface_z_m)
        ax.plot([0], [zs], "*", color="white", markersize=12, markeredgecolor="black",
                label=f"{source.vehicle} (source)")
        ax.set_ylim(water.deepest_m, 0.0)
        ax.set_xlim(0.0, water.range_m)
        ax.set_xlabel(f"range from {source.vehicle} (m)")
        ax.set_ylabel("depth (m)")
        ax.set_title(f"channel {name}: BELLHOP TL at {fields.frequency_hz / 1000:g} kHz, source at {zs:.0f} m")
        ax.legend(loc="lower right", fontsize=8)
        fig.tight_layout()
        for fmt in formats:
            path = os.path.join(out, f"water-{name}.{fmt}")
            fig.savefig(path, dpi=dpi)
            written.append(path)
        plt.close(fig)
    return written


def _draw_tracks(ax, poses: dict, source_vehicle: str, track: list, surface_z_m: float) -> None:
    """Every other vehicle's track on ``ax``, in the source's plane: its horizontal distance from the source's
    vehicle at each of its pose samples (the source's nearest sample in time when none is at the same time),
    and its depth; a dot at its last sample."""
    here = dict(track)
    times = [t for t, _ in track]
    for vehicle, samples in sorted(poses.items()):
        points = [(t, p) for t, p in samples if p is not None]
        if vehicle == source_vehicle or not points:
            continue
        rs, zs_ = [], []
        for t, p in points:
            a = here.get(t) or here[times[min(range(len(times)), key=lambda i: abs(times[i] - t))]]
            rs.append(math.hypot(p[0] - a[0], p[1] - a[1]))
            zs_.append(p[2] - surface_z_m)
        ax.plot(rs, zs_, lw=1.5, label=vehicle)
        ax.plot(rs[-1:], zs_[-1:], "o", color=ax.lines[-1].get_color())
