"""Draws docs/figures/per-presets.png, docs/channel-models.md's "Choosing an error model" figure: PER(d) of a
64-byte frame for the EvoLogics presets with `error: {kind: physical}` (the model's defaults: Thorp,
k = 1.5, shipping 0.5, no wind) at AT!L0 and AT!L3, and for the S100 preset's expression.

matplotlib is an optional extra (`pip install 'hilgate[report]'`); without it this says so and stops.
Run: .venv/bin/python docs/figures/per_presets.py
"""

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))

SIZE = 64


def main() -> int:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("this figure needs matplotlib: pip install 'hilgate[report]'", file=sys.stderr)
        return 1
    import numpy as np

    from hilgate.scene import load_scene_text

    presets = ("evologics-s2cr-7-17", "evologics-s2cr-18-34", "evologics-s2cr-48-78")
    fig, (ac, rf) = plt.subplots(1, 2, figsize=(10, 4), gridspec_kw={"width_ratios": [2, 1]})
    for preset, colour in zip(presets, ("C0", "C1", "C2")):
        for level, style in ((0, "-"), (3, ":")):
            scene = load_scene_text(
                "channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0, 0, 0]}}}\n"
                f"links: {{a: {{vehicle: a, model: {preset}, error: {{kind: physical}}, acoustic: {{level: {level}}}}}}}\n",
                "<figure>")
            model = scene.links["a"].params.error
            d = np.linspace(10, 10_000, 600)
            ac.plot(d / 1000, [model.per(x, SIZE) for x in d], style, color=colour,
                    label=f"{preset.removeprefix('evologics-')} AT!L{level}")
    ac.set_xlabel("distance (km)")
    ac.set_ylabel(f"PER, {SIZE}-byte frames")
    ac.set_title("EvoLogics presets, error: {kind: physical}")
    ac.legend(fontsize=8)
    ac.grid(alpha=0.3)
    scene = load_scene_text("channels: {rf: {speed_mps: 2.25e7}}\nvehicles: {a: {pose: {static: [0, 0, 0]}}}\n"
                            "links: {a: {vehicle: a, model: s100}}\n", "<figure>")
    model = scene.links["a"].params.error
    d = np.linspace(0.5, 6.5, 300)
    rf.plot(d, [model.per(x, SIZE) for x in d], color="C3", label="s100: 6e-13 * d^13.7 per bit")
    rf.set_xlabel("distance (m)")
    rf.set_title("S100 preset (RF expression)")
    rf.legend(fontsize=8)
    rf.grid(alpha=0.3)
    fig.tight_layout()
    out = os.path.join(HERE, "per-presets.png")
    fig.savefig(out, dpi=110)
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
