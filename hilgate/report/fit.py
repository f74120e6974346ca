"""Maximum-likelihood fits of frame loss against distance, for ``hilgate fit``.

Each observation is a Bernoulli trial (delivered or lost) with the model's PER at its distance and
size, so the log-likelihood is Σ log(1 − PERᵢ) over delivered frames + Σ log PERᵢ over lost ones.
Forms:

- ``power``: PER = 1 − (1 − a·d^b)^(8L), the paper's BER(d) = a·d^b per bit (UWSim-NET's S100 fit).
  Fitted as (c, b) with a·d^b = exp(c + b·ln(d/d₀)), d₀ the geometric mean distance, which keeps
  the two parameters nearly uncorrelated; a's interval comes back through the delta method.
- ``logistic``: PER = 1 / (1 + exp(−(β₀ + β₁·d))), per frame whatever its size.
- ``physical``: the physical model's free parameters, as a function ``per(θ, d, size)`` handed in
  by the caller (``hilgate fit`` fits the effective source level; the spreading factor k comes from
  the frames' RSSI when they carry it, :func:`fit_rssi`, since delivered/lost alone hardly separate
  k from the level).

The optimiser is Nelder–Mead followed by Newton steps on a finite-difference Hessian (two or three
parameters; numpy is the only dependency — scipy would bring 40 MB for this).  The covariance is the
inverse observed information at the optimum; intervals are Wald intervals (±1.96 σ), and the PER
band at a distance is the delta-method interval of the fitted curve there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

__all__ = ["Fit", "fit_power", "fit_logistic", "fit_function", "fit_rssi", "bins", "Z95"]

Z95 = 1.959963984540054
EPS = 1e-300


@dataclass
class Fit:
    form: str
    names: tuple[str, ...]
    theta: np.ndarray            # the fitted (internal) parameters
    cov: np.ndarray              # their covariance
    loglik: float
    n: int
    per: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]  # (theta, d, size) -> PER

    def stderr(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))

    def interval(self, i: int) -> tuple[float, float]:
        s = self.stderr()[i]
        return float(self.theta[i] - Z95 * s), float(self.theta[i] + Z95 * s)

    def curve(self, d: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """PER at ``d`` for frames of ``size`` bytes, with the 95 % band (delta method on the logit,
        so that the band stays inside [0, 1])."""
        d = np.asarray(d, dtype=float)
        sizes = np.full_like(d, size)
        p = np.clip(self.per(self.theta, d, sizes), 1e-15, 1 - 1e-15)
        logit = np.log(p) - np.log1p(-p)
        grad = np.empty((len(self.theta), len(d)))
        for i in range(len(self.theta)):
            h = 1e-5 * max(1.0, abs(self.theta[i]))
            up, down = self.theta.copy(), self.theta.copy()
            up[i] += h
            down[i] -= h
            pu = np.clip(self.per(up, d, sizes), 1e-15, 1 - 1e-15)
            pd = np.clip(self.per(down, d, sizes), 1e-15, 1 - 1e-15)
            grad[i] = ((np.log(pu) - np.log1p(-pu)) - (np.log(pd) - np.log1p(-pd))) / (2 * h)
        se = np.sqrt(np.maximum(np.einsum("in,ij,jn->n", grad, self.cov, grad), 0.0))
        low = 1 / (1 + np.exp(-(logit - Z95 * se)))
        high = 1 / (1 + np.exp(-(logit + Z95 * se)))
        return p, low, high


def _loglik(per_fn, theta, d, size, lost) -> float:
    p = per_fn(theta, d, size)
    if not np.all(np.isfinite(p)):
        return -math.inf
    p = np.clip(p, EPS, 1.0)
    q = np.clip(1.0 - p, EPS, 1.0)
    return float(np.sum(np.where(lost, np.log(p), np.log(q))))


def _nelder_mead(f, x0: np.ndarray, step: np.ndarray, iterations: int = 2000) -> np.ndarray:
    n = len(x0)
    simplex = [x0] + [x0 + np.eye(n)[i] * step[i] for i in range(n)]
    values = [f(x) for x in simplex]
    for _ in range(iterations):
        order = np.argsort(values)
        simplex = [simplex[i] for i in order]
        values = [values[i] for i in order]
        if abs(values[-1] - values[0]) < 1e-10 * (1 + abs(values[0])) and \
                max(np.max(np.abs(s - simplex[0])) for s in simplex) < 1e-9:
            break
        centroid = np.mean(simplex[:-1], axis=0)
        reflected = centroid + (centroid - simplex[-1])
        fr = f(reflected)
        if fr < values[0]:
            expanded = centroid + 2 * (centroid - simplex[-1])
            fe = f(expanded)
            simplex[-1], values[-1] = (expanded, fe) if fe < fr else (reflected, fr)
        elif fr < values[-2]:
            simplex[-1], values[-1] = reflected, fr
        else:
            contracted = centroid + 0.5 * (simplex[-1] - centroid)
            fc = f(contracted)
            if fc < values[-1]:
                simplex[-1], values[-1] = contracted, fc
            else:
                simplex = [simplex[0] + 0.5 * (s - simplex[0]) for s in simplex]
                values = [f(s) for s in simplex]
    return simplex[int(np.argmin(values))]


def _hessian(f, x: np.ndarray) -> np.ndarray:
    n = len(x)
    h = np.array([1e-4 * max(1.0, abs(v)) for v in x])
    hess = np.empty((n, n))
    f0 = f(x)
    for i in range(n):
        for j in range(i, n):
            if i == j:
                e = np.eye(n)[i] * h[i]
                hess[i, i] = (f(x + e) - 2 * f0 + f(x - e)) / (h[i] * h[i])
            else:
                ei, ej = np.eye(n)[i] * h[i], np.eye(n)[j] * h[j]
                hess[i, j] = hess[j, i] = (f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej) + f(x - ei - ej)) / (
                    4 * h[i] * h[j])
    return hess


def fit_function(form: str, names: Sequence[str], per_fn, x0: Sequence[float], step: Sequence[float],
                 d: Sequence[float], size: Sequence[int], delivered: Sequence[bool]) -> Fit:
    """Maximise the binomial likelihood of ``per_fn(theta, d, size)``; the covariance is the inverse of
    the observed information."""
    d_arr = np.asarray(d, dtype=float)
    size_arr = np.asarray(size, dtype=float)
    lost = ~np.asarray(delivered, dtype=bool)
    if len(d_arr) == 0:
        raise ValueError("no frames to fit")

    def nll(theta):
        value = -_loglik(per_fn, np.asarray(theta, dtype=float), d_arr, size_arr, lost)
        return value if math.isfinite(value) else 1e300

    theta = _nelder_mead(nll, np.asarray(x0, dtype=float), np.asarray(step, dtype=float))
    for _ in range(20):  # polish with Newton steps: Nelder–Mead stops short of the curvature's scale
        hess = _hessian(nll, theta)
        grad = np.array([(nll(theta + e) - nll(theta - e)) / (2 * e[i])
                         for i, e in enumerate(np.eye(len(theta)) * np.array([1e-6 * max(1, abs(v)) for v in theta]))])
        try:
            delta = np.linalg.solve(hess, grad)
        except np.linalg.LinAlgError:
            break
        candidate = theta - delta
        if nll(candidate) > nll(theta):
            break
        theta = candidate
        if np.max(np.abs(delta)) < 1e-10:
            break
    hess = _hessian(nll, theta)
    try:
        # an optimum must curve upwards in every direction; where it does not, the data cannot tell
        # the parameters apart, and the intervals say so (infinite) rather than look precise
        cov = np.linalg.inv(hess) if np.all(np.linalg.eigvalsh(hess) > 0) else None
    except np.linalg.LinAlgError:
        cov = None
    if cov is None:
        cov = np.full((len(theta), len(theta)), np.inf)
    return Fit(form, tuple(names), theta, cov, -nll(theta), len(d_arr), per_fn)


def fit_power(d, size, delivered) -> tuple[Fit, float]:
    """The paper's form; returns the fit in (c, b) and d₀ (a = exp(c − b·ln d₀))."""
    d_arr = np.maximum(np.asarray(d, dtype=float), 1e-6)
    d0 = float(np.exp(np.mean(np.log(d_arr))))

    def per(theta, dd, ss):
        c, b = theta
        with np.errstate(over="ignore", invalid="ignore"):
            r = np.exp(np.minimum(c + b * np.log(np.maximum(dd, 1e-6) / d0), 0.0))  # a bit error rate is ≤ 1
            return -np.expm1(8 * ss * np.log1p(-np.minimum(r, 1 - 1e-16)))

    lost = 1 - np.mean(np.asarray(delivered, dtype=float))
    mean_bits = max(8.0, 8 * float(np.mean(np.asarray(size, dtype=float))))  # (frames of 0 bytes: one byte)
    c0 = math.log(max(min(-math.log1p(-min(max(lost, 1e-4), 0.9999)) / mean_bits, 0.5), 1e-12))
    fit = fit_function("power", ("c", "b"), per, (c0, 5.0), (1.0, 2.0), d_arr, size, delivered)
    return fit, d0


def _exp(x: float) -> float:
    """exp, infinite beyond a float's range (an interval the data cannot bound) instead of an error."""
    return math.exp(x) if x < 709.0 else math.inf


def power_parameters(fit: Fit, d0: float) -> dict[str, tuple[float, float, float]]:
    """a and b with their 95 % intervals (a through log a = c − b·ln d₀, delta method)."""
    c, b = fit.theta
    log_a = c - b * math.log(d0)
    jac = np.array([1.0, -math.log(d0)])
    se_log_a = math.sqrt(max(float(jac @ fit.cov @ jac), 0.0))
    lo_b, hi_b = fit.interval(1)
    return {"a": (_exp(log_a), _exp(log_a - Z95 * se_log_a), _exp(log_a + Z95 * se_log_a)),
            "b": (float(b), lo_b, hi_b), "log_a": (log_a, log_a - Z95 * se_log_a, log_a + Z95 * se_log_a)}


def fit_logistic(d, size, delivered) -> Fit:
    """PER = 1 / (1 + exp(−(β₀ + β₁·d))), fitted in the scaled distance d/s (s the mean distance)."""
    d_arr = np.asarray(d, dtype=float)
    scale = float(np.mean(d_arr)) or 1.0

    def per_scaled(theta, dd, ss):
        return 1.0 / (1.0 + np.exp(-(theta[0] + theta[1] * dd / scale)))

    fit = fit_function("logistic", ("beta0", "beta1"), per_scaled, (0.0, 0.0), (1.0, 1.0), d_arr, size, delivered)
    # back to β₁ per metre
    jac = np.diag([1.0, 1.0 / scale])
    theta = np.array([fit.theta[0], fit.theta[1] / scale])

    def per(theta_, dd, ss):
        return 1.0 / (1.0 + np.exp(-(theta_[0] + theta_[1] * dd)))

    return Fit("logistic", fit.names, theta, jac @ fit.cov @ jac, fit.loglik, fit.n, per)


def fit_rssi(d, rssi, alpha_db_per_km: float) -> tuple[float, float, float, float]:
    """Least squares of RSSI = c − k·10·log10(d) − α·d/1000 (α known): returns k, its standard error,
    c and the residual standard deviation.  RSSI is in the modem's own unit (dB re 1 V for EvoLogics):
    only its slope against distance is used."""
    d_arr = np.maximum(np.asarray(d, dtype=float), 1.0)
    y = np.asarray(rssi, dtype=float) + alpha_db_per_km * d_arr / 1000.0
    x = -10.0 * np.log10(d_arr)
    design = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    residual = y - design @ coef
    dof = max(len(y) - 2, 1)
    sigma2 = float(residual @ residual) / dof
    cov = sigma2 * np.linalg.pinv(design.T @ design)
    return float(coef[1]), float(math.sqrt(max(cov[1, 1], 0.0))), float(coef[0]), math.sqrt(sigma2)


def bins(d: Sequence[float], delivered: Sequence[bool], count: int = 10) -> list[tuple[float, float, int, int]]:
    """Equal-width distance bins over the data: (low, high, frames, lost) each."""
    d_arr = np.asarray(d, dtype=float)
    lost = ~np.asarray(delivered, dtype=bool)
    low, high = float(d_arr.min()), float(d_arr.max())
    if high <= low:
        return [(low, high, len(d_arr), int(lost.sum()))]
    edges = np.linspace(low, high, count + 1)
    index = np.minimum(np.searchsorted(edges, d_arr, side="right") - 1, count - 1)
    return [(float(edges[i]), float(edges[i + 1]), int(np.sum(index == i)), int(np.sum(lost[index == i])))
            for i in range(count)]
