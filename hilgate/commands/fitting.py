"""``hilgate fit TRACE``: an ``error:`` block for the scene from what the links of a run sent and received.

This module only wires the parts together (it sits above the rooms, with the commands): the scene says
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

from ..report.fit import Z95, Fit, bins, fit_function, fit_logistic, fit_power, fit_rssi, power_parameters
from ..report.observations import FitError, LinkInfo, Observations, links_of_view, observations, read_events
from ..report.tracefile import TraceError, printable

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


def _links_of_scene(scene: Any) -> dict[str, LinkInfo]:
    """A scene file's links, as the trace's ``scene_view`` would give them (one way to the fit)."""
    from ..scene.view import scene_view

    return links_of_view(scene_view(scene), scene.path)


def _physical_model(view: Any) -> Any:
    """The physical error model a link's error view describes (None: another kind)."""
    from ..models.physical import Acoustic, Environment, PhysicalErrorModel

    if not isinstance(view, dict) or view.get("kind") != "physical":
        return None

    def front(value: Any) -> Any:
        fields = dict(value)
        fields["band_khz"] = tuple(fields["band_khz"])
        fields["decodes"] = tuple(fields.get("decodes") or ())
        return Acoustic(**fields)

    try:
        sender = view.get("sender")
        rate = view.get("sender_bitrate_bps")
        return PhysicalErrorModel(Environment(**dict(view["env"])), front(view["acoustic"]), float(view["bitrate_bps"]),
                                  None if sender is None else front(sender), None if rate is None else float(rate))
    except (KeyError, TypeError, ValueError) as exc:
        raise FitError(f"the trace's physical error model is not one hilgate builds ({type(exc).__name__}: "
                       f"{printable(str(exc))})") from None


def _physical_fit(data: Observations) -> tuple[Fit, dict, str]:
    """The effective source level by binomial maximum likelihood, with the spreading factor k from the
    frames' RSSI when at least ``MIN_RSSI`` delivered frames carry it (else the scene's k, held)."""
    from ..models.acoustics import ber

    receivers = sorted({o.dst for o in data.frames})
    views = [data.links[r].error for r in receivers]
    models = [_physical_model(view) for view in views]
    if not all(m is not None for m in models) or len({repr(v) for v in views}) != 1:
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
    """Which links were real, and where each rode, come from the trace's own ``run`` and ``reload``
    lines (the scene as it was at each moment); ``scene_path`` (``--scene``) replaces them for the
    whole trace, and is needed for a trace that carries no scene (``hilgate sim``'s, an older
    daemon's whose scene file is gone)."""
    from ..report.tracedata import ReportError, pick_run, trace_runs

    if model not in MODELS:
        raise FitError(f"--model must be one of {', '.join(MODELS)}, not {model!r}")
    if not (math.isfinite(pose_gap_s) and pose_gap_s >= 0 and math.isfinite(window_s) and window_s >= 0):
        raise FitError("--pose-gap and --window must be seconds (finite, not negative)")
    try:
        chosen = pick_run(trace_runs(trace), run)
    except ReportError as exc:
        raise FitError(str(exc)) from None
    start, follow = _starting_links(trace, chosen, scene_path, overrides)
    receivers = set(links) if links else None
    try:
        data = observations(read_events(trace, chosen.first_line, chosen.last_line), start, simulated=simulated,
                            receivers=receivers, pose_gap_s=pose_gap_s, window_s=window_s, follow_scene=follow,
                            path=trace)
    except TraceError as exc:
        raise FitError(str(exc)) from None
    if len(data.frames) < 2 or all(o.delivered for o in data.frames) or not any(o.delivered for o in data.frames):
        kept = sum(1 for o in data.frames if o.delivered)
        raise FitError(f"nothing to fit: {len(data.frames)} frames ({kept} delivered) after leaving out "
                       f"{_excluded(data) or 'none'}; a fit needs both losses and deliveries")
    size = int(median(o.size for o in data.frames))
    fit, params, block = _fitted(model, data)
    return FitResult(model, fit, block, params, data, size)


def _starting_links(trace: str, chosen: Any, scene_path: str | None,
                    overrides: tuple[str, ...]) -> tuple[dict[str, LinkInfo] | None, bool]:
    """The links at the run's start and whether to follow the trace's scene lines: ``--scene`` for the whole
    trace, else the trace's own scene (an older daemon's trace: its scene file, if still there)."""
    from ..scene.load import load_scene

    start: dict[str, LinkInfo] | None = None
    follow = scene_path is None
    if scene_path is not None:
        start = _links_of_scene(load_scene(scene_path, list(overrides)))
    elif not chosen.has_view:
        if not chosen.path:
            raise FitError(f"{trace} does not carry its scene (a hilgate sim trace): give it with --scene SCENE")
        if not os.path.exists(chosen.path):
            raise FitError(f"the trace's scene {chosen.path} is not there any more; give it with --scene")
        start, follow = _links_of_scene(load_scene(chosen.path, list(overrides))), False  # an older daemon's trace
    return start, follow


def _fitted(model: str, data: Observations) -> tuple[Any, dict, str]:
    """``model`` fitted to ``data``'s frames: the fit, its parameters and the ``error:`` block they make."""
    d = [o.d for o in data.frames]
    sizes = [o.size for o in data.frames]
    delivered = [o.delivered for o in data.frames]
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
        fit, params, block = _physical_fit(data)
    return fit, params, block


def _excluded(data: Observations) -> str:
    return ", ".join(f"{printable(cause, 40)} {n}" for cause, n in sorted(data.excluded.items()))


FORMS = {
    "power": "PER = 1 - (1 - a*d^b)^(8L)",
    "logistic": "PER = 1 / (1 + exp(-(beta0 + beta1*d)))",
    "physical": "PER from SNR = SL - k*10*log10(d) - alpha*d - NL (the receivers' physical model; SL fitted)",
}


def print_fit(result: FitResult, out: TextIO, bin_count: int = 10) -> None:
    data, fit = result.data, result.fit
    receivers = sorted({o.dst for o in data.frames})
    lost = sum(1 for o in data.frames if not o.delivered)
    print(f"{len(data.frames)} frames ({lost} lost) heard or missed by {', '.join(map(printable, receivers))}; "
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
