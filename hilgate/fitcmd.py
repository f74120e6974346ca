"""``hilgate fit TRACE``: an ``error:`` block for the scene from what the links of a run sent and received.

This module only wires the parts together (it sits above the rooms, like the CLI): the scene says
which vehicle each link rides and which links are real (:mod:`hilgate.scene`), the trace gives the
frames and poses (:mod:`hilgate.report.observations`), the fit is a binomial maximum likelihood
(:mod:`hilgate.report.fit`), and the physical form's PER comes from :mod:`hilgate.models.physical`.
"""

from __future__ import annotations

import math
import os
from statistics import median
from typing import Any, TextIO

import numpy as np

from .report.fit import Z95, Fit, bins, fit_function, fit_logistic, fit_power, fit_rssi, power_parameters
from .report.observations import FitError, LinkInfo, Observations, observations, read_events

__all__ = ["run_fit", "FitError", "FitResult"]

MODELS = ("power", "logistic", "physical")
MIN_RSSI = 10


class FitResult:
    """What ``run_fit`` found: the fit, its ready ``error:`` block and the frames behind it."""

    def __init__(self, model: str, fit: Fit, block: str, params: dict[str, tuple[float, float, float]],
                 data: Observations, size: int):
        self.model = model
        self.fit = fit
        self.block = block
        self.params = params
        self.data = data
        self.size = size


def _scene_of(events: list[dict], scene_path: str | None, trace: str) -> str:
    if scene_path:
        return scene_path
    for event in events:
        if event.get("ev") == "run" and event.get("path"):
            if os.path.exists(event["path"]):
                return event["path"]
            raise FitError(f"the trace's scene {event['path']} is not there any more; give it with --scene")
    raise FitError(f"{trace} does not name its scene (a hilgate sim trace): give it with --scene SCENE")


def _physical_fit(scene: Any, data: Observations) -> tuple[Fit, dict, str]:
    """The effective source level by binomial maximum likelihood, with the spreading factor k from the
    frames' RSSI when at least ``MIN_RSSI`` delivered frames carry it (else the scene's k, held)."""
    from .models.acoustics import ber
    from .models.physical import PhysicalErrorModel

    receivers = sorted({o.dst for o in data.frames})
    models = [scene.links[r].params.error for r in receivers]
    if not all(isinstance(m, PhysicalErrorModel) for m in models) or len({m for m in models}) != 1:
        raise FitError("--model physical needs the receiving links to share one error: {kind: physical} "
                       "(their band, modulation and water are the starting point); fit power or logistic instead")
    model = models[0]
    modulation = model.acoustic.modulation
    ber_of = np.vectorize(lambda ebn0: ber(modulation, ebn0), otypes=[float])
    alpha = model.alpha_db_per_km
    heard = [(o.d, o.rssi) for o in data.frames if o.delivered and o.rssi is not None]
    params: dict[str, tuple[float, float, float]] = {}
    if len(heard) >= MIN_RSSI:
        k, k_se, _, _ = fit_rssi([d for d, _ in heard], [r for _, r in heard], alpha)
        params["spreading"] = (k, k - Z95 * k_se, k + Z95 * k_se)
        k_note = f"from the RSSI of {len(heard)} frames"
    else:
        k = model.env.spreading
        k_note = f"held at the scene's value: fewer than {MIN_RSSI} frames carry RSSI"

    def per(theta, d, size):
        dd = np.maximum(d, 1.0)
        snr = theta[0] - (k * 10 * np.log10(dd) + alpha * dd / 1000.0) - model.noise_db
        b = np.clip(ber_of(snr + model.ebn0_offset_db), 0.0, 1.0 - 1e-16)
        return -np.expm1(8 * size * np.log1p(-b))

    fit = fit_function("physical", ("source_level_db",), per, (model.source_db,), (5.0,),
                       [o.d for o in data.frames], [o.size for o in data.frames], [o.delivered for o in data.frames])
    params = {"source_level_db": (float(fit.theta[0]), *fit.interval(0)), **params}
    sl = fit.theta[0]
    block = (f"acoustic: {{source_level_db: {sl:.1f}}}   # effective, at the AT!L level the modem sent with\n"
             f"error: {{kind: physical, spreading: {k:.3f}}}   # k {k_note}")
    if not 1.0 <= k <= 2.0:
        block += f"\n# k = {k:.3f} is outside [1, 2], what a scene accepts: this water is not the model's"
    return fit, params, block


def run_fit(trace: str, scene_path: str | None = None, model: str = "power", links: list[str] | None = None,
            simulated: bool = False, run: str | None = None, pose_gap_s: float = 2.0, window_s: float = 5.0,
            overrides: tuple[str, ...] = ()) -> FitResult:
    from .report.figures import ReportError, pick_run, trace_runs
    from .scene.load import load_scene

    if model not in MODELS:
        raise FitError(f"--model must be one of {', '.join(MODELS)}, not {model!r}")
    try:
        chosen = pick_run(trace_runs(trace), run)
    except ReportError as exc:
        raise FitError(str(exc)) from None
    events = read_events(trace, chosen.first_line, chosen.last_line)
    scene = load_scene(_scene_of(events, scene_path, trace), list(overrides))
    infos = {name: LinkInfo(link.vehicle, link.backend, link.params.address, link.params.tx_channel,
                            link.params.rx_channel) for name, link in scene.links.items()}
    receivers = None
    if links:
        unknown = [name for name in links if name not in infos]
        if unknown:
            raise FitError(f"no link {unknown[0]!r} in scene {scene.path}; links: {', '.join(infos)}")
        receivers = set(links)
    data = observations(events, infos, simulated=simulated, receivers=receivers, pose_gap_s=pose_gap_s,
                        window_s=window_s)
    if len(data.frames) < 2 or all(o.delivered for o in data.frames) or not any(o.delivered for o in data.frames):
        kept = sum(1 for o in data.frames if o.delivered)
        raise FitError(f"nothing to fit: {len(data.frames)} frames ({kept} delivered) after leaving out "
                       f"{_excluded(data) or 'none'}; a fit needs both losses and deliveries")
    d = [o.d for o in data.frames]
    sizes = [o.size for o in data.frames]
    delivered = [o.delivered for o in data.frames]
    size = int(median(sizes))
    if model == "power":
        fit, d0 = fit_power(d, sizes, delivered)
        params = power_parameters(fit, d0)
        a, b = params["a"][0], params["b"][0]
        block = f'error: {{unit: bit, expr: "{a:.6g} * d^{b:.6g}"}}'
        params = {"a": params["a"], "b": params["b"]}
    elif model == "logistic":
        fit = fit_logistic(d, sizes, delivered)
        params = {name: (float(fit.theta[i]), *fit.interval(i)) for i, name in enumerate(fit.names)}
        b0, b1 = fit.theta
        block = f'error: {{unit: packet, expr: "1 / (1 + exp(-({b0:.6g} + {b1:.6g} * d)))"}}'
    else:
        fit, params, block = _physical_fit(scene, data)
    return FitResult(model, fit, block, params, data, size)


def _excluded(data: Observations) -> str:
    return ", ".join(f"{cause} {n}" for cause, n in sorted(data.excluded.items()))


FORMS = {
    "power": "PER = 1 - (1 - a*d^b)^(8L)",
    "logistic": "PER = 1 / (1 + exp(-(beta0 + beta1*d)))",
    "physical": "PER from SNR = SL - k*10*log10(d) - alpha*d - NL (the receivers' physical model; SL fitted)",
}


def print_fit(result: FitResult, out: TextIO, bin_count: int = 10) -> None:
    data, fit = result.data, result.fit
    receivers = sorted({o.dst for o in data.frames})
    lost = sum(1 for o in data.frames if not o.delivered)
    print(f"{len(data.frames)} frames ({lost} lost) heard or missed by {', '.join(receivers)}; "
          f"left out: {_excluded(data) or 'none'}", file=out)
    print(f"model {result.model}: {FORMS[result.model]}", file=out)
    for name, (value, low, high) in result.params.items():
        print(f"  {name} = {value:.6g}   (95 % interval {low:.6g} .. {high:.6g})", file=out)
    print(f"  log-likelihood {fit.loglik:.2f}", file=out)
    print("", file=out)
    print(result.block, file=out)
    print("", file=out)
    print(f"{'d from':>8} {'d to':>8} {'frames':>7} {'lost':>5} {'PER seen':>9} {'PER fit':>9}  95 % band "
          f"(frames of {result.size} bytes)", file=out)
    d = [o.d for o in data.frames]
    for low, high, n, k in bins(d, [o.delivered for o in data.frames], bin_count):
        if n == 0:
            print(f"{low:8.2f} {high:8.2f} {0:7d}", file=out)
            continue
        p, lo, hi = fit.curve(np.array([(low + high) / 2]), result.size)
        print(f"{low:8.2f} {high:8.2f} {n:7d} {k:5d} {k / n:9.4f} {p[0]:9.4f}  {lo[0]:.4f} .. {hi[0]:.4f}", file=out)


def plot_fit(result: FitResult, path: str, bin_count: int = 10) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise FitError("--plot needs matplotlib, an optional extra: pip install 'hilgate[report]'") from None
    data, fit = result.data, result.fit
    d = np.array([o.d for o in data.frames])
    grid = np.linspace(max(d.min(), 1e-3), d.max(), 200)
    p, lo, hi = fit.curve(grid, result.size)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.fill_between(grid, lo, hi, alpha=0.25, label="95 % band")
    ax.plot(grid, p, label=f"{result.model} fit")
    for low, high, n, k in bins(d, [o.delivered for o in data.frames], bin_count):
        if n:
            q = k / n
            err = 1.96 * math.sqrt(max(q * (1 - q), 1e-12) / n)
            ax.errorbar([(low + high) / 2], [q], yerr=[[min(q, err)], [min(1 - q, err)]], fmt="o", color="k", ms=3)
    ax.set_xlabel("distance (m)")
    ax.set_ylabel(f"PER ({result.size}-byte frames)")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
