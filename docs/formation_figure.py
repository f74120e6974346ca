#!/usr/bin/env python3
"""docs/paper.md's formation figure (docs/figures/exp3-formation.png) from the virtual-time run of UWSim-NET's
third experiment: ``scenes/paper-exp3-formation-virtual.yaml`` (examples/formation/apps.py in ``hilgate
sim``) under CS-ALOHA and S-FAMA, 60 simulated seconds, the scene's seed.  Deterministic: running it again
draws the same curves.  Nothing in it is typed by hand:

    python docs/formation_figure.py            # a few seconds; `make paper` runs it with the other paper scripts
"""

from __future__ import annotations

import argparse
import io
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from hilgate.scene import load_scene  # noqa: E402
from hilgate.sim.simulate import Simulation  # noqa: E402

SCENE = os.path.join(ROOT, "scenes", "paper-exp3-formation-virtual.yaml")
SLOTS = {"follower1": (-1.5, 0.0, 0.0), "follower2": (0.0, -1.5, 0.0), "follower3": (-1.5, -1.5, 0.0)}
MACS = {"cs-aloha": [], "s-fama": ["links.*.mac.backoff_s=null"]}  # as examples/formation/run.py --virtual
SECONDS = 60.0


def errors(mac: str) -> tuple[list[tuple[float, str, float]], int]:
    """Each follower's distance from its slot at every traced pose instant, and the scene's seed."""
    import json

    scene = load_scene(SCENE, [f"links.*.mac.protocol={mac}", *MACS[mac]])
    out = io.StringIO()
    Simulation(scene, trace=out, until=SECONDS).run()
    poses: dict[float, dict[str, list[float]]] = {}
    for line in out.getvalue().splitlines():
        event = json.loads(line)
        if event.get("ev") == "pose" and event.get("position"):
            poses.setdefault(event["t"], {})[event["vehicle"]] = event["position"]
    rows = []
    for t in sorted(poses):
        if "leader" in poses[t]:
            for follower, slot in SLOTS.items():
                if follower in poses[t]:
                    expected = [l + s for l, s in zip(poses[t]["leader"], slot)]
                    rows.append((t, follower, math.dist(poses[t][follower], expected)))
    return rows, scene.seed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=os.path.join(HERE, "figures", "exp3-formation.png"))
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 5.2), sharex=True, sharey=True)
    styles = {"follower1": ("-", 2.6), "follower2": ("--", 1.6), "follower3": (":", 1.2)}
    for ax, mac in zip(axes, MACS):
        rows, seed = errors(mac)
        series = {f: [(t, e) for t, g, e in rows if g == f] for f in SLOTS}
        spread = max(abs(a[1] - b[1]) for f in SLOTS for a, b in zip(series[f], series["follower1"]))
        for follower, (style, width) in styles.items():
            ax.plot([t for t, _ in series[follower]], [e for _, e in series[follower]], style, lw=width,
                    label=follower)
        everything = [e for _, _, e in rows]
        ax.set_title(f"{mac}: mean {sum(everything) / len(everything):.3f} m, max {max(everything):.3f} m "
                     f"(the three followers' curves coincide within {spread * 1000:.1f} mm)", fontsize=9)
        ax.set_ylabel("from the slot (m)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
        print(f"{mac}: mean {sum(everything) / len(everything):.3f} m, max {max(everything):.3f} m")
    axes[-1].set_xlabel("model time (s)")
    fig.suptitle(f"Formation error in virtual time: scenes/paper-exp3-formation-virtual.yaml, seed {seed}, "
                 f"0–{SECONDS:g} s", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {os.path.relpath(args.out, ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
