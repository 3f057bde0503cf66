"""Stiction quantification by Hammerstein identification (methods.md §6.1; thesis §2.5).

The loop from OP to PV is modelled as a Kano stiction model (S, J) followed by a linear ARX
model (Srinivasan et al. 2005; Jelali 2008; Bacci di Capaci & Scali 2014):

    v = kano(OP; S, J)                      (estimated valve position)
    PV(k) + a1·PV(k−1) + a2·PV(k−2) = b1·v(k−nk) + b2·v(k−nk−1) + c

For every (S, J) on a grid (S up to 0.9 × the OP excursion, J/S from 0 to 1) the ARX part is
fitted by least squares (all pairs in one batched solve), the delay nk is taken from the
cross-correlation of the increments, and the pair is ranked by the *simulation* error of the
model (one-step prediction error hardly depends on (S, J), methods §6.1). The best pair is
refined on a finer local grid. Integrating (level) loops are fitted on the PV increments.

Reliability rules (methods §6.1, reconstructed [R]): the estimate is reported only when the
simulated fit is good enough, the stiction model explains clearly more than a linear valve,
the optimum is well posed (not on the grid edge, a compact low-error region) and a second
model structure (ARX on increments, robust to non-stationary disturbances) agrees on S.
Otherwise S and J are None and ``reasons`` says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sp_fft
from scipy.signal import butter, lfilter

from plantcheck.diagnosis.signal_tools import FloatArray
from plantcheck.diagnosis.valve_models import kano_grid


@dataclass(frozen=True)
class QuantificationParams:
    """Grid and acceptance rules of the Hammerstein quantification [R]."""

    n_s: int = 20
    """Grid points over S in (0, s_max_fraction × OP excursion]."""
    n_ratio: int = 11
    """Grid points over J/S in [0, max_ratio]."""
    max_ratio: float = 1.0
    """Largest J/S on the grid (1 = 'no offset' case; Kano allows overshoot J > S)."""
    s_max_fraction: float = 0.9
    """S_max as a fraction of the OP peak-to-peak excursion (methods §6.1)."""
    refine: int = 7
    """Points per axis of the local refinement grid."""
    max_delay_fraction: float = 0.25
    """Largest delay searched, as a fraction of the oscillation period (or 30 samples)."""
    min_fit: float = 60.0
    """Simulation FIT (%) needed for a reported estimate (methods §6.1 rule 2)."""
    max_score_ratio: float = 0.7
    """Best simulation error must be at most this × that of a linear valve (rule 3)."""
    compact_tol: float = 1.05
    """The low-error region is where the error is within this factor of the minimum (rule 4)."""
    max_region_extent: float = 0.5
    """Its S-extent must be below this fraction of S* (rule 4)."""
    max_structure_disagreement: float = 0.3
    """Relative difference of S* between ARX and ARX-on-increments (rule 5)."""
    min_moves: int = 4
    """A candidate valve trajectory must move at least this many times."""
    reference_fraction: float = 0.02
    """Deadband of the near-linear reference valve, as a fraction of S_max (rule 3)."""
    highpass_fraction: float = 0.2
    """Prefilter cut-off as a fraction of the oscillation frequency (slow loads removed)."""


@dataclass(frozen=True)
class QuantificationResult:
    """Estimated stiction (% of valve travel, i.e. of OP units) and its reliability."""

    S: float | None
    J: float | None
    reliable: bool
    reasons: list[str]
    S_best: float
    J_best: float
    fit: float
    score_ratio: float
    delay_samples: int
    S_increments: float | None = None
    surface: dict[str, FloatArray] = field(default_factory=dict, repr=False)


@dataclass(frozen=True)
class _GridFit:
    S: FloatArray
    J: FloatArray
    score: FloatArray
    fit: FloatArray
    delay: np.ndarray
    valves: FloatArray


def _delays(v: FloatArray, y: FloatArray, max_delay: int) -> np.ndarray:
    """Per row of ``v``: the lag 1..max_delay maximising |Σ Δv(k−l)·Δy(k)|."""
    dv = np.diff(v, axis=1)
    dy = np.diff(y)
    n = dy.size
    nfft = sp_fft.next_fast_len(2 * n, real=True)
    cross = sp_fft.irfft(
        np.conj(sp_fft.rfft(dv, nfft, axis=1)) * sp_fft.rfft(dy, nfft)[None, :], nfft, axis=1
    )
    lags = cross[:, 1 : max_delay + 1]
    return np.asarray(1 + np.argmax(np.abs(lags), axis=1), dtype=np.intp)


def _fit_arx(v: FloatArray, y: FloatArray, delay: np.ndarray) -> tuple[FloatArray, FloatArray]:
    """Batched ARX(2,2,nk) least squares and simulation; returns (score, fit%) per row."""
    n_p, n = v.shape
    start = int(delay.max()) + 2
    m = n - start
    yk = y[start:]
    y1 = y[start - 1 : n - 1]
    y2 = y[start - 2 : n - 2]
    rows = np.arange(n_p)[:, None]
    idx = np.arange(start, n)[None, :] - delay[:, None]
    v1 = v[rows, idx]
    v2 = v[rows, idx - 1]
    # Normal equations in blocks: the PV regressors [-y1, -y2, 1] are shared by every pair.
    ymat = np.column_stack([-y1, -y2, np.ones(m)])
    a_mat = np.empty((n_p, 5, 5))
    a_mat[:, :3, :3] = ymat.T @ ymat
    yv1 = v1 @ ymat
    yv2 = v2 @ ymat
    a_mat[:, :3, 3] = yv1
    a_mat[:, :3, 4] = yv2
    a_mat[:, 3, :3] = yv1
    a_mat[:, 4, :3] = yv2
    a_mat[:, 3, 3] = np.sum(v1 * v1, axis=1)
    a_mat[:, 4, 4] = np.sum(v2 * v2, axis=1)
    a_mat[:, 3, 4] = a_mat[:, 4, 3] = np.sum(v1 * v2, axis=1)
    b_vec = np.empty((n_p, 5))
    b_vec[:, :3] = ymat.T @ yk
    b_vec[:, 3] = v1 @ yk
    b_vec[:, 4] = v2 @ yk
    a_mat += 1e-9 * np.eye(5)[None, :, :] * np.trace(a_mat, axis1=1, axis2=2)[:, None, None]
    theta = np.linalg.solve(a_mat, b_vec[:, :, None])[:, :, 0]
    score = np.full(n_p, np.inf)
    fit = np.full(n_p, -np.inf)
    warm = max(start, n // 10)
    den = float(np.sum((y[warm:] - y[warm:].mean()) ** 2)) or 1.0
    for i in range(n_p):
        a1, a2, c, b1, b2 = theta[i]
        if not (abs(a2) < 1.0 and abs(a1) < 1.0 + a2):
            # closed-loop least squares can return an unstable fit: reflect the poles inside
            # the unit circle (same spectrum shape) and simulate that model
            roots = np.roots([1.0, a1, a2])
            roots = np.where(np.abs(roots) > 1.0, 1.0 / np.conj(roots), roots)
            roots = np.where(np.abs(roots) > 0.999, 0.999 * roots / np.abs(roots), roots)
            a1, a2 = np.real(np.poly(roots))[1:]
        d = int(delay[i])
        num = np.concatenate((np.zeros(d), [b1, b2]))
        den_poly = np.array([1.0, a1, a2])
        ysim = lfilter(num, den_poly, v[i] - v[i, 0]) + (c + (b1 + b2) * v[i, 0]) / (1 + a1 + a2)
        # the simulation starts at rest: the first tenth of the window is its warm-up
        err = (y - ysim)[warm:]
        score[i] = float(np.mean(err**2))
        fit[i] = 100.0 * (1.0 - math.sqrt(float(np.sum(err**2)) / den))
    return score, fit


Prefilter = tuple[FloatArray, FloatArray]


def highpass_prefilter(cutoff_cycles: float) -> Prefilter:
    """2nd-order Butterworth high-pass at ``cutoff_cycles`` cycles per sample."""
    b, a = butter(2, min(max(2.0 * cutoff_cycles, 1e-4), 0.5), btype="highpass")
    return np.asarray(b, dtype=np.float64), np.asarray(a, dtype=np.float64)


def _evaluate(
    u: FloatArray,
    y: FloatArray,
    S: FloatArray,
    J: FloatArray,
    max_delay: int,
    min_moves: int,
    prefilter: Prefilter,
    valves: FloatArray | None = None,
) -> _GridFit:
    v = kano_grid(u, S, J) if valves is None else valves
    moves = np.sum(np.abs(np.diff(v, axis=1)) > 1e-12, axis=1)
    b, a = prefilter
    # the same linear filter on both sides keeps PV = G·v and removes slow load drift
    vf = lfilter(b, a, v - v[:, :1], axis=1)
    yf = lfilter(b, a, y - y[0])
    delay = _delays(vf, yf, max_delay)
    score, fit = _fit_arx(vf, yf, delay)
    score = np.where(moves >= min_moves, score, np.inf)
    return _GridFit(S, J, score, fit, delay, v)


def _grid(s_max: float, p: QuantificationParams) -> tuple[FloatArray, FloatArray]:
    s_vals = np.linspace(s_max / p.n_s, s_max, p.n_s)
    r_vals = np.linspace(0.0, p.max_ratio, p.n_ratio)
    sg, rg = np.meshgrid(s_vals, r_vals, indexing="ij")
    return sg.ravel(), (sg * rg).ravel()


def _search(
    u: FloatArray, y: FloatArray, max_delay: int, p: QuantificationParams, pf: Prefilter
) -> tuple[_GridFit, float, float, float]:
    """Coarse grid, then local refinement; returns (coarse fit, S*, J*, best score)."""
    s_max = p.s_max_fraction * float(np.ptp(u))
    s_c, j_c = _grid(s_max, p)
    coarse = _evaluate(u, y, s_c, j_c, max_delay, p.min_moves, pf)
    i = int(np.argmin(coarse.score))
    s_best, j_best, best = float(coarse.S[i]), float(coarse.J[i]), float(coarse.score[i])
    ds = s_max / p.n_s
    s_f = np.linspace(max(ds / 4, s_best - ds), s_best + ds, p.refine)
    r_best = j_best / s_best if s_best > 0 else 0.0
    dr = p.max_ratio / (p.n_ratio - 1)
    r_f = np.linspace(max(0.0, r_best - dr), min(p.max_ratio, r_best + dr), p.refine)
    sg, rg = np.meshgrid(s_f, r_f, indexing="ij")
    fine = _evaluate(u, y, sg.ravel(), (sg * rg).ravel(), max_delay, p.min_moves, pf)
    k = int(np.argmin(fine.score))
    if fine.score[k] < best:
        s_best, j_best, best = float(fine.S[k]), float(fine.J[k]), float(fine.score[k])
    return coarse, s_best, j_best, best


def quantify_stiction(
    op: FloatArray,
    pv: FloatArray,
    ts: float,
    period_s: float | None = None,
    integrating: bool = False,
    params: QuantificationParams | None = None,
) -> QuantificationResult:
    """Estimate S and J (% of valve travel) from OP and PV by Hammerstein identification.

    Parameters
    ----------
    op, pv:
        Controller output (% 0–100) and process variable of an oscillating, constant-SP,
        automatic-mode window without gaps.
    ts:
        Sample time, s (only used to bound the delay search through ``period_s``).
    period_s:
        Oscillation period, s; bounds the delay search to a quarter period.
    integrating:
        Level-type loop: the linear part is fitted on PV increments.
    """
    p = params or QuantificationParams()
    u = np.asarray(op, dtype=np.float64)
    u = u - u.mean()
    y = np.asarray(pv, dtype=np.float64)
    if integrating:
        y = np.concatenate(([0.0], np.diff(y)))
    y = y - y.mean()
    max_delay = 30
    period_samples = period_s / ts if period_s else y.size / 10.0
    if period_s:
        max_delay = int(min(max(2, p.max_delay_fraction * period_samples), 200))
    pf = highpass_prefilter(p.highpass_fraction / period_samples)
    coarse, s_best, j_best, best = _search(u, y, max_delay, p, pf)
    # Reference "linear valve": a deadband of 2 % of the grid range. With v = OP exactly, the
    # closed-loop regressors are collinear (OP is a linear function of past PV) and the fit is
    # meaningless; a tiny deadband removes the collinearity without modelling stiction.
    s_ref = p.reference_fraction * p.s_max_fraction * float(np.ptp(u))
    lin = _evaluate(u, y, np.array([s_ref]), np.array([0.0]), max_delay, 0, pf)
    score_lin = float(lin.score[0])
    v_best = _evaluate(u, y, np.array([s_best]), np.array([j_best]), max_delay, 0, pf)
    fit = float(v_best.fit[0])
    delay = int(v_best.delay[0])
    ratio = best / score_lin if math.isfinite(score_lin) and score_lin > 0 else 0.0
    reasons: list[str] = []
    if not math.isfinite(best):
        reasons.append("no stiction model gave a stable linear part")
    if fit < p.min_fit:
        reasons.append(f"model fit {fit:.0f} % below {p.min_fit:.0f} %")
    if ratio > p.max_score_ratio:
        reasons.append(
            f"stiction model explains little more than a linear valve (error ratio {ratio:.2f})"
        )
    s_max = p.s_max_fraction * float(np.ptp(u))
    if s_best >= 0.97 * s_max:
        reasons.append("S* on the edge of the grid (as large as the OP excursion)")
    good = coarse.score <= p.compact_tol * best
    if good.any():
        extent = float(coarse.S[good].max() - coarse.S[good].min())
        if s_best > 0 and extent > p.max_region_extent * s_best:
            reasons.append(f"S not identifiable: low-error region spans {extent:.2f} % of OP")
    # rule 5: a second structure, ARX on increments (non-stationary disturbance)
    s_inc: float | None = None
    if not integrating:
        dy = np.concatenate(([0.0], np.diff(y)))
        s_inc = _search_increments(coarse, dy, max_delay, p)
        if s_inc is not None and s_best > 0:
            if abs(s_inc - s_best) / s_best > p.max_structure_disagreement:
                reasons.append(
                    f"model structures disagree on S ({s_best:.2f} vs {s_inc:.2f} %): "
                    "disturbance-affected"
                )
    reliable = not reasons
    surface = {"S": coarse.S, "J": coarse.J, "score": coarse.score}
    return QuantificationResult(
        S=s_best if reliable else None,
        J=j_best if reliable else None,
        reliable=reliable,
        reasons=reasons,
        S_best=s_best,
        J_best=j_best,
        fit=fit,
        score_ratio=ratio,
        delay_samples=delay,
        S_increments=s_inc,
        surface=surface,
    )


def _search_increments(
    coarse: _GridFit, dy: FloatArray, max_delay: int, p: QuantificationParams
) -> float | None:
    """S* of the same grid with the linear part fitted between increments of v and PV
    (ARX with integrated noise: robust to non-stationary disturbances, methods §6.1 rule 5)."""
    v = coarse.valves
    dv = np.concatenate((np.zeros((v.shape[0], 1)), np.diff(v, axis=1)), axis=1)
    moves = np.sum(np.abs(dv) > 1e-12, axis=1)
    delay = _delays(v, np.cumsum(dy), max_delay)
    score, _ = _fit_arx(dv, dy, delay)
    score = np.where(moves >= p.min_moves, score, np.inf)
    if not np.isfinite(score).any():
        return None
    return float(coarse.S[int(np.argmin(score))])
