"""Process identification from a closed-loop window (issue 48 item 1): first order plus dead
time (FOPDT) for self-regulating loops, integrator plus dead time (IPDT) for levels, from the
controller output OP (%) to the process variable PV (engineering units).

The controller output is recorded, so closed-loop data identify the process by the direct
method (Ljung 1999, §13.4), provided something other than the PV's own noise moves OP:
set-point steps, or loads large against the noise. The model is fitted as an *output error*
model (its simulated output against the measured PV, never the one-step prediction an ARX fit
uses, which a coloured load biases towards a fast, low-gain process):

    PV(k) ≈ K·x_{τ,θ}(k) + c_s + g_s·k,

x_{τ,θ} being OP delayed by θ through a unit first-order lag of time constant τ (for an IPDT
model its running integral), c_s the operating point of stretch s and g_s a slow drift the
loads leave in it. For each (τ, θ) the linear parameters are a least-squares solution; (τ, θ)
are searched on a coarse grid of block means and then refined at full rate, θ to a quarter
sample (separable least squares, Golub & Pereyra 2003). Where set-point steps are present
only the stretches after them are fitted, about four open-loop settling times each: there
OP moves for the step and the loads matter least.

Each parameter has a standard deviation: K's from the regression's covariance, τ's and θ's
from the width of the fit's valley (the values whose residual sum of squares is within one
noise variance of the best, the profile-likelihood interval), with the residual's correlation
counted (fewer independent samples than samples). The fit is 100·(1 − ‖residual‖/‖PV − mean‖),
the figure MATLAB's ``compare`` prints. Where the data cannot identify the process the result
says why instead of guessing.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import (
    FloatArray,
    block_means,
    centred_time,
    detrend,
    first_order_lags,
    log_grid,
    mean,
    noise_sigma,
    sorted_unique,
    std,
)

ModelKind = Literal["fopdt", "ipdt"]


@dataclass(frozen=True)
class IdentificationParams:
    """Limits of the identification."""

    max_dead_time_share: float = 0.25
    """Dead times tried: up to this share of the fitted stretch."""
    max_dead_time_samples: int = 600
    """... and at most this many samples."""
    time_constants: int = 16
    """Time constants on the coarse grid, log-spaced from 0.3 sample to a third of the data."""
    min_fit_percent: float = 70.0
    """A simulated-output fit below this is no model (the data do not show the process)."""
    min_excitation: float = 4.0
    """OP must move by this many times its sample-to-sample noise σ: below, only noise moves
    the loop and the direct method reads the controller's inverse (Ljung 1999, §13.4)."""
    min_auto_share: float = 0.5
    """Share of the window in automatic below which the loop is called 'in manual'."""
    min_input_share: float = 1e-6
    """OP's part of the fitted PV (the gain times its lagged OP) must vary by at least this
    share of the PV's own variation: a drift term can fit a ramping PV exactly and leave the
    gain at rounding level (3e-12 on a PV ramp beside a wandering OP), which SIMC would turn
    into a controller gain of 1e14."""
    step_before: int = 20
    """Samples kept before each set-point step when the stretches around steps are fitted."""
    min_samples: int = 60


@dataclass(frozen=True)
class ProcessModel:
    """An identified process, or why there is none (``kind`` None, ``reason``).

    K is in PV units per % of OP for ``fopdt`` and in PV units per second per % of OP for
    ``ipdt``; τ (``fopdt`` only) and θ in seconds, each with its standard deviation (``*_sd``);
    ``fit_percent`` the simulated-output fit; ``source`` what excited the data: ``set-point
    steps`` or ``routine`` operation."""

    kind: ModelKind | None
    K: float | None = None
    tau_s: float | None = None
    theta_s: float | None = None
    K_sd: float | None = None
    tau_sd: float | None = None
    theta_sd: float | None = None
    fit_percent: float | None = None
    source: str | None = None
    reason: str = ""

    def to_json(self) -> dict[str, object]:
        """contracts §2 ``tuning.model`` (the ``*_sd``, ``source`` and ``reason`` optional)."""
        return {
            "type": self.kind,
            "K": _r(self.K),
            "tau_s": _r(self.tau_s),
            "theta_s": _r(self.theta_s),
            "K_sd": _r(self.K_sd),
            "tau_sd": _r(self.tau_sd),
            "theta_sd": _r(self.theta_sd),
            "fit_percent": None if self.fit_percent is None else round(self.fit_percent, 1),
            "source": self.source,
            "reason": self.reason or None,
        }


def _r(x: float | None) -> float | None:
    """Three significant digits: what an identified parameter can mean."""
    return None if x is None or x == 0 else float(f"{x:.3g}")


def no_model(reason: str) -> ProcessModel:
    return ProcessModel(kind=None, reason=reason)


def _regressors(
    u: FloatArray, taus: FloatArray, integrating: bool, ts: float
) -> NDArray[np.float64]:
    """x for each pole (rows): OP through a unit first-order lag started at rest at the
    window's first OP, or OP's running integral (s·%) for an integrating process; then
    delayed by one sample (a zero-order hold: PV(k) answers OP up to k−1)."""
    if integrating:
        x = np.cumsum(u - u[0])[None, :] * ts
    else:
        x = first_order_lags(u, np.exp(-1.0 / np.maximum(taus, 1e-9)).tolist()) - u[0]
    return np.concatenate([np.zeros((x.shape[0], 1)), x[:, :-1]], axis=1)


def _sse_grid(
    y: FloatArray, x: NDArray[np.float64], delays: NDArray[np.int64], segments: list[slice]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Residual sum of squares and gain K of PV ≈ K·x(k − d) + c_s + g_s·k over the samples
    of ``segments`` (disjoint, ascending, each with its own level c_s and drift g_s), for
    every row of ``x`` (a time constant) and every delay d in ``delays`` (ascending): arrays
    (poles, delays).

    Each segment's level and drift are projected out of PV directly and out of x through
    running sums. Only the samples some delay reaches are kept (each segment and the
    ``max(delays) − min(delays)`` samples after it, in shift coordinates); over them Σx·PV
    is one matrix-vector product per delay, and Σx, Σk·x and Σx² over each shifted segment
    are its sum at one shift plus what entered minus what left. The gathered copy of x per
    delay this replaces made the search three times slower. x is centred first (a constant
    in x is a level, projected out anyway) so that the sums lose no digits."""
    starts = np.array([s.start for s in segments], dtype=np.int64)
    lengths = np.array([s.stop - s.start for s in segments], dtype=np.int64)
    max_d = int(delays[-1])
    reach = max_d - int(delays[0])
    # x(k − d) = xc[o_s + k − start_s + r] for a sample k of segment s, r = max_d − d in
    # 0 .. reach (before the window x is 0): each segment and the reach after it, in turn
    spans = [(a - max_d, a - max_d + n + reach) for a, n in zip(starts, lengths, strict=True)]
    xc = np.zeros((x.shape[0], sum(hi - lo for lo, hi in spans)))
    at = 0
    for lo, hi in spans:
        # a span reaching back past the window's start is 0 there (x before it is 0); one
        # that ends before the start (a short first segment read at a long dead time) is 0
        # throughout
        src = x[:, max(0, lo) : max(0, hi)]
        xc[:, at + max(0, -lo) : at + max(0, -lo) + src.shape[1]] = src
        at += hi - lo
    xc -= x.mean(axis=1, keepdims=True)
    offsets = np.concatenate([[0], np.cumsum(lengths + reach)[:-1]])
    yc = np.zeros(xc.shape[1] - reach)
    for seg, o in zip(segments, offsets.tolist(), strict=True):
        ys = y[seg]
        t, tt = centred_time(ys.size)
        yc[o : o + ys.size] = ys - ys.mean() - (t * (float(t @ ys) / tt) if tt > 0 else 0.0)
    syy = float(yc @ yc)
    width = yc.size
    sxy = np.stack([xc[:, r : r + width] @ yc for r in (max_d - delays).tolist()], axis=1)
    k = np.arange(xc.shape[1], dtype=np.float64)
    at_zero = np.empty((3, x.shape[0], starts.size))
    for i, (o, n) in enumerate(zip(offsets.tolist(), lengths.tolist(), strict=True)):
        part = xc[:, o : o + n]
        at_zero[:, :, i] = part.sum(axis=1), part @ k[o : o + n], np.einsum("pk,pk->p", part, part)
    steps = offsets[:, None] + np.arange(reach)
    came, went = xc[:, steps + lengths[:, None]], xc[:, steps]
    entered = np.stack(
        [came - went, came * (steps + lengths[:, None]) - went * steps, came * came - went * went]
    )
    moved = np.zeros((3, x.shape[0], starts.size, reach + 1))
    np.cumsum(entered, axis=3, out=moved[..., 1:])
    by_shift = at_zero[..., None] + moved
    r = max_d - delays
    window = np.moveaxis(by_shift[:, :, :, r], 3, 2)  # (3, poles, delays, segments)
    s0, s1, s2 = window[0], window[1], window[2]
    length = lengths.astype(np.float64)
    first = offsets[None, :] + r[:, None]  # each shifted segment's first sample
    drift = s1 - (first + (length - 1.0) / 2.0) * s0  # Σ (k − the segment's middle)·x
    t_norm = length * (length * length - 1.0) / 12.0  # Σ (k − middle)²
    drift_sq = np.divide(drift * drift, t_norm, out=np.zeros_like(drift), where=t_norm > 0)
    sxx = np.sum(s2 - s0 * s0 / length - drift_sq, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(sxx > 1e-12, sxy / sxx, 0.0)
        sse = np.where(sxx > 1e-12, syy - sxy * gain, syy)
    return sse, gain


def _segments(n: int, steps: NDArray[np.int64], before: int, length: int | None) -> list[slice]:
    """The stretches fitted: the whole window without set-point steps; else from ``before``
    samples ahead of each step to ``length`` samples after it (None: the next step), where
    the step's OP moves dominate the loads."""
    if steps.size == 0:
        return [slice(0, n)]
    out: list[slice] = []
    bounds = [*steps.tolist(), n]
    for k, nxt in itertools.pairwise(bounds):
        lo = max(0, k - before, out[-1].stop if out else 0)
        hi = nxt if length is None else min(nxt, k + length)
        if hi - lo >= 10:
            out.append(slice(lo, hi))
    return out or [slice(0, n)]


def _width(values: FloatArray, sse: FloatArray, best: int, allowance: float) -> float:
    """Half the span of ``values`` whose SSE is within ``allowance`` of the best one's (the
    profile-likelihood 1-σ interval), at least half a grid step."""
    inside = values[sse <= sse[best] + allowance]
    steps = np.diff(np.sort(values))
    half_step = float(steps[steps > 0].min()) / 2.0 if np.any(steps > 0) else 0.0
    return max(float(inside.max() - inside.min()) / 2.0, half_step)


@dataclass(frozen=True)
class _Fit:
    """The best (τ, θ) of one search, in samples, with its gain, SSE and the SSE profiles
    along τ and θ through it (for the parameters' widths)."""

    tau: float
    theta: float
    K: float
    sse: float
    x: FloatArray
    taus: FloatArray
    sse_tau: FloatArray
    thetas: FloatArray
    sse_theta: FloatArray


ALTERNATIONS = 3
"""Rounds of the fine search's θ-then-τ walk (it stops early once τ stays)."""
FRACTIONS = (0.0, 0.25, 0.5, 0.75)
"""Sub-sample dead times of the fine search: a dead time of 0.6 s sampled every 0.5 s is no
whole number of samples, and rounding it is a 20 % error."""


COARSE_SAMPLES = 500
"""The coarse search runs on block means of about this many samples: it only has to find
the valley, which the fine search at full rate then walks down."""


def _coarse(
    pv: FloatArray,
    op: FloatArray,
    ts: float,
    integrating: bool,
    segments: list[slice],
    p: IdentificationParams,
    samples: int = 0,
    delay_points: int = 32,
) -> tuple[float, int, int]:
    """The best (τ, θ) of a coarse grid of ``delay_points`` dead times on block means of
    about ``samples`` (0: ``COARSE_SAMPLES``): τ and θ in samples, and the grid's θ step in
    samples."""
    span = sum(s.stop - s.start for s in segments)
    b = max(1, span // (samples or COARSE_SAMPLES))
    cseg = [slice(s.start // b, max(s.start // b + 1, s.stop // b)) for s in segments]
    cspan = sum(s.stop - s.start for s in cseg)
    max_d = int(min(p.max_dead_time_samples / b, max(1, p.max_dead_time_share * cspan)))
    taus = (
        np.array([0.0]) if integrating else log_grid(0.3, max(2.0, cspan / 3.0), p.time_constants)
    )
    coarse_d = _coarse_delays(max_d, delay_points)
    pv_b, op_b = block_means(pv, b), block_means(op, b)
    sse, _ = _sse_grid(pv_b, _regressors(op_b, taus, integrating, ts * b), coarse_d, cseg)
    i, j = np.unravel_index(int(np.argmin(sse)), sse.shape)
    # the grid's step where the best one lies: the fine search walks that far either side
    gaps = np.diff(coarse_d)
    at = int(j)
    d_step = int(max(gaps[max(at - 1, 0)], gaps[min(at, gaps.size - 1)])) if gaps.size else 1
    return float(taus[i]) * b, int(coarse_d[j]) * b, d_step * b


def _coarse_delays(max_d: int, points: int = 32) -> NDArray[np.int64]:
    """Dead times of the coarse grid (samples): every sample up to 12, then log-spaced to
    ``max_d``. An even grid over a long range steps past short dead times: the stretches
    after set-point steps of a fast loop (θ 2 samples, a grid of 0, 5, 10 ...) were fitted
    at θ 5 with a time constant shrunk to make up for it, which the fine search around it
    never left (fit 61 % where 91 % was there)."""
    dense = np.arange(min(max_d, 12) + 1)
    if max_d <= 12:
        return dense.astype(np.int64)
    wide = log_grid(13, max_d, points - dense.size)
    # ascending already: 0 .. 12, then a log grid from 13 up, rounded
    return sorted_unique(np.concatenate([dense, np.round(wide)])).astype(np.int64)


def _search(
    pv: FloatArray,
    op: FloatArray,
    ts: float,
    integrating: bool,
    segments: list[slice],
    p: IdentificationParams,
) -> _Fit:
    """The coarse grid (``_coarse``), then at full rate: about 16 dead times around its best
    with τ from 0.6 to 1.6 times its value; every whole and quarter sample of θ around that
    best; τ from 0.85 to 1.18 times it at the best θ."""
    tau0, d0, width = _coarse(pv, op, ts, integrating, segments, p)
    fine_d = _fine_delays(d0, width)
    taus = np.array([0.0]) if integrating else tau0 * log_grid(0.6, 1.6, 7)
    sse, _ = _sse_grid(pv, _regressors(op, taus, integrating, ts), fine_d, segments)
    i, j = np.unravel_index(int(np.argmin(sse)), sse.shape)
    tau1, d1 = float(taus[i]), int(fine_d[j])
    step = int(np.max(np.diff(fine_d))) if fine_d.size > 1 else 1
    near_d = np.arange(max(0, d1 - step), d1 + step + 1)
    thetas = (near_d[None, :] + np.asarray(FRACTIONS)[:, None]).ravel().astype(np.float64)
    for _ in range(ALTERNATIONS):
        # θ in quarter samples at τ1, then τ around τ1 at that θ
        x = _regressors(op, np.array([tau1]), integrating, ts)
        xf = np.concatenate([_fractional(x, f) for f in FRACTIONS])
        sse_f, _ = _sse_grid(pv, xf, near_d, segments)  # (fraction, delay)
        f, j = np.unravel_index(int(np.argmin(sse_f)), sse_f.shape)
        frac, d2 = FRACTIONS[f], int(near_d[j])
        near_taus = np.array([0.0]) if integrating else tau1 * log_grid(0.85, 1.18, 7)
        xt = _fractional(_regressors(op, near_taus, integrating, ts), frac)
        sse_t, gain = _sse_grid(pv, xt, np.array([d2]), segments)
        k = int(np.argmin(sse_t[:, 0]))
        if integrating or near_taus[k] == tau1:
            break
        tau1 = float(near_taus[k])
    return _Fit(
        tau=float(near_taus[k]),
        theta=d2 + frac,
        K=float(gain[k, 0]),
        sse=float(sse_t[k, 0]),
        x=_delayed(xt[k], d2),
        taus=near_taus.astype(np.float64),
        sse_tau=sse_t[:, 0],
        thetas=thetas,
        sse_theta=sse_f.ravel(),
    )


def _fine_delays(d0: int, width: int) -> NDArray[np.int64]:
    """At most 17 whole dead times (samples) across the coarse grid's step either side of
    its best ``d0``."""
    grid = np.round(np.linspace(max(0, d0 - width), d0 + width, min(2 * width + 1, 17)))
    return sorted_unique(grid).astype(np.int64)


def _fractional(x: NDArray[np.float64], frac: float) -> NDArray[np.float64]:
    """Rows of ``x`` delayed by ``frac`` of a sample (linear interpolation)."""
    shifted = np.concatenate([np.zeros((x.shape[0], 1)), x[:, :-1]], axis=1)
    return np.asarray((1.0 - frac) * x + frac * shifted)


def _delayed(x: FloatArray, d: int) -> FloatArray:
    out = np.zeros_like(x)
    out[d:] = x[: x.size - d]
    return out


def identify_process(
    pv: FloatArray,
    op: FloatArray,
    ts: float,
    *,
    integrating: bool = False,
    sp_steps: NDArray[np.int64] | None = None,
    auto_share: float | None = None,
    params: IdentificationParams | None = None,
) -> ProcessModel:
    """FOPDT (``integrating`` False) or IPDT model from OP (%) to PV over a window sampled
    every ``ts`` seconds; ``sp_steps`` the samples where the set point steps (the fit is then
    confined to the stretches after them, about four open-loop settling times each, as a
    coarse first fit finds them), ``auto_share`` the share of the window in automatic (None:
    unknown)."""
    p = params or IdentificationParams()
    pv = np.asarray(pv, dtype=np.float64)
    op = np.asarray(op, dtype=np.float64)
    n = pv.size
    if n < p.min_samples or not (np.all(np.isfinite(pv)) and np.all(np.isfinite(op))):
        return no_model(f"too few usable samples ({n}; at least {p.min_samples} needed)")
    if auto_share is not None and auto_share < p.min_auto_share:
        return no_model(
            f"the loop was in manual for {100 * (1 - auto_share):.0f} % of the window: "
            "identify it from a window in automatic, or from a bump test in manual"
        )
    op_noise = noise_sigma(op)  # the sample-to-sample part: an oscillation is no noise
    smooth = np.convolve(op, np.full(5, 0.2), mode="valid") if n >= 5 else op
    op_move = float(np.ptp(smooth))  # an integrating loop's OP moves for a while only
    if op_move <= p.min_excitation * op_noise or op_move < 0.2:
        return no_model(
            f"OP moved by {op_move:.2g} % only: nothing excites the process (a set-point "
            "step or a bump test would)"
        )
    steps = np.asarray(sp_steps if sp_steps is not None else [], dtype=np.int64)
    segments = _segments(n, steps, p.step_before, None)
    if steps.size:
        tau0, d0, _ = _coarse(pv, op, ts, integrating, segments, p)
        settle = int(4.0 * (tau0 + d0)) + p.step_before
        segments = _segments(n, steps, p.step_before, max(settle, 4 * p.step_before))
    fit = _search(pv, op, ts, integrating, segments, p)
    rows = np.concatenate([np.arange(s.start, s.stop) for s in segments])
    total = sum(float(np.sum((pv[s] - pv[s].mean()) ** 2)) for s in segments)
    fit_pct = 100.0 * (1.0 - math.sqrt(max(fit.sse, 0.0) / total)) if total > 0 else 0.0
    if fit_pct < p.min_fit_percent or fit.K == 0.0:
        return no_model(
            f"the best model explains the PV poorly (fit {fit_pct:.0f} %, "
            f"{p.min_fit_percent:g} % needed): loads or noise move the PV more than OP does"
        )
    x_rows, pv_rows = fit.x[rows], pv[rows]
    xr = x_rows - mean(x_rows)
    sxx = float(xr @ xr)
    # OP's part of the fitted PV, |K| times its lagged OP's σ, against the PV's σ
    if abs(fit.K) * math.sqrt(sxx / rows.size) < p.min_input_share * std(pv_rows):
        return no_model(
            "the PV does not answer OP in this window (OP's part of the best model is at "
            "rounding level; a drift explains the PV): a set-point step or a bump test would "
            "show the process"
        )
    lag1 = _residual_lag1(pv_rows, x_rows, fit.K)
    # an exact fit (PV and OP both interpolated straight across a historian's gap) leaves
    # an SSE of rounding, which may be a hair below 0
    allowance = max(fit.sse, 0.0) / max(rows.size - 5, 1) * (1.0 + lag1) / (1.0 - lag1)
    K_sd = math.sqrt(allowance / sxx) if sxx > 0 else None
    spread = _gain_spread(pv, fit.x, segments)
    if K_sd is not None and spread is not None:
        K_sd = max(K_sd, spread)
    best_theta = int(np.argmin(fit.sse_theta))
    theta_sd = _width(fit.thetas, fit.sse_theta, best_theta, allowance) * ts
    tau_s = tau_sd = None
    if not integrating:
        tau_s = fit.tau * ts
        tau_sd = _width(fit.taus, fit.sse_tau, int(np.argmin(fit.sse_tau)), allowance) * ts
    return ProcessModel(
        kind="ipdt" if integrating else "fopdt",
        K=fit.K,
        tau_s=tau_s,
        theta_s=fit.theta * ts,
        K_sd=K_sd,
        tau_sd=tau_sd,
        theta_sd=theta_sd,
        fit_percent=fit_pct,
        source="set-point steps" if steps.size else "routine",
    )


def _gain_spread(pv: FloatArray, x: FloatArray, segments: list[slice]) -> float | None:
    """The standard error of the gain from its scatter between the fitted stretches (each
    its own gain, level and drift at the best τ and θ), None for fewer than two stretches.

    A load step inside one stretch after a set-point step moves PV as OP did not: that
    stretch's gain is off (0.6 against 1.8 on a simulated temperature loop), the pooled gain
    with it, and the regression's standard error, which takes the residual for noise, stays
    small. The scatter between stretches sees it (a jackknife-like standard error, Efron &
    Tibshirani 1993), and the proposal then takes the model at its cautious edge."""
    gains = []
    for s in segments:
        if s.stop - s.start < 10 or np.ptp(x[s]) <= 0:
            continue
        _, gain = _sse_grid(pv, x[None, :], np.zeros(1, dtype=np.int64), [s])
        gains.append(float(gain[0, 0]))
    if len(gains) < 2:
        return None
    return float(np.std(gains, ddof=1) / math.sqrt(len(gains)))


def _residual_lag1(pv: FloatArray, x: FloatArray, K: float) -> float:
    """Lag-1 autocorrelation of the fit's residual (clipped to 0-0.95): a correlated
    residual has fewer independent samples than samples."""
    n = pv.size
    r = pv - K * x
    a = np.column_stack([np.ones(n), np.arange(n, dtype=np.float64)])
    coef, *_ = np.linalg.lstsq(a, r, rcond=None)
    e = r - a @ coef
    den = float(e @ e)
    rho = float(e[1:] @ e[:-1]) / den if den > 0 else 0.0
    return min(max(rho, 0.0), 0.95)


@dataclass(frozen=True)
class QuickProcessFit:
    """A rough FOPDT/IPDT model for the learned decision's evidence (issue 46): K in PV
    units per % of OP (per sample and % for an IPDT model), τ and θ in samples, ``fit`` the
    simulated-output fit as a fraction (1 perfect, 0 no better than the mean, negative
    worse)."""

    K: float
    tau: float
    theta: float
    fit: float


QUICK = IdentificationParams(time_constants=8)
"""The quick fit's grid: half the time constants of the full search."""
QUICK_COARSE_SAMPLES = 250
"""Block means of the quick fit's coarse grid: a tenth of the full identification's time."""


def quick_process_fit(
    pv: FloatArray, op: FloatArray, *, integrating: bool = False
) -> QuickProcessFit | None:
    """The process seen from OP to PV over the whole window, in 1-2 ms per 3,600 samples:
    the full identification's coarse grid on ~250 block means, then its dead time refined at
    full rate (every sample within a grid step either side, τ at 0.7, 1 and 1.4 times the
    coarse one). No set-point stretches, no sub-sample θ, no standard deviations and no fit
    threshold: the decision learns how far to trust it (its ``fit``) where
    ``identify_process`` would decline. None where OP does not move at all or the
    window is shorter than the identification's minimum."""
    pv = np.asarray(pv, dtype=np.float64)
    op = np.asarray(op, dtype=np.float64)
    n = pv.size
    if n < QUICK.min_samples or float(np.ptp(op)) <= 0.0:
        return None
    segments = [slice(0, n)]
    tau0, d0, width = _coarse(
        pv, op, 1.0, integrating, segments, QUICK, samples=QUICK_COARSE_SAMPLES, delay_points=16
    )
    fine_d = _fine_delays(d0, width)
    fine_taus = np.array([0.0]) if integrating else tau0 * np.array([0.7, 1.0, 1.4])
    sse, gain = _sse_grid(pv, _regressors(op, fine_taus, integrating, 1.0), fine_d, segments)
    i, j = np.unravel_index(int(np.argmin(sse)), sse.shape)
    # the SSE is over PV with its level and drift projected out (``_sse_grid``): so is this
    yc = detrend(pv)
    total = float(yc @ yc)
    fit = 1.0 - math.sqrt(max(float(sse[i, j]), 0.0) / total) if total > 0 else 0.0
    return QuickProcessFit(
        K=float(gain[i, j]), tau=float(fine_taus[i]), theta=float(fine_d[j]), fit=max(fit, -1.0)
    )
