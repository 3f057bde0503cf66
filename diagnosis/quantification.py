"""Stiction quantification by Hammerstein identification (methods.md §6.1; thesis §2.5).

The loop from OP to PV is modelled as a Kano stiction model (S, J) followed by a linear ARX
model (Srinivasan et al. 2005; Jelali 2008; Bacci di Capaci & Scali 2014):

    v = kano(OP; S, J)                      (estimated valve position)
    PV(k) + a1·PV(k−1) + a2·PV(k−2) = b1·v(k−nk) + b2·v(k−nk−1) + c

For every (S, J) on a grid (S up to 0.9 × the OP excursion, J/S from 0 to 1) the ARX part is
fitted by least squares (all pairs in one batched solve), the delay nk is the one with the
smallest least-squares residual among the delays a scan of every delay on a subset of the grid
found for its good pairs, and the pair is ranked by the *simulation* error of the
model (one-step prediction error hardly depends on (S, J), methods §6.1). The best pair is
refined on a finer local grid. The same search runs with a He valve (He et al. 2007); a He
valve never forgets where it started (on a ramp it slips every J from there, in a cycle each
slip lands where the last one put it), so each He pair is tried from a few starting positions
over one slip, and the best few S values again from twenty: a He fit is sharp in the start
(about a tenth of J wide) and in S (under 1 %). Last, every J/S at the best S is tried again, a
He valve from twenty starts (the J polish): the refinement around the coarse J/S may keep a J
that fits worse than another J from that J's own best start. A Kano valve starts stuck with the
first OP sample at the edge of its break band facing the bulk of the OP, so it cannot lock (a
band centred on the first sample, BDSIM's start, may hold a large valve still for the whole
window). OP and PV are prefiltered alike: a steep (4th-order) high-pass a fifth of the
oscillation frequency down removes slow loads, which would bias the ARX model, and a low-pass
at five times it removes noise. An external oscillation slower than the loop's cycle (a
sinusoidal load from elsewhere in the plant) is only partly removed by the high-pass: when OP
shows it as a spectral line, a notch at its frequency is added to the prefilter (Bacci di
Capaci, Scali & Pannocchia 2016: a model of the additive disturbance improves the estimate when
a disturbance acts together with stiction). Integrating (level) loops use the same structure:
the high-pass removes the integrator's drift, and fitting PV increments instead only amplified
noise.

Reliability rules (methods §6.1, reconstructed [R]): the estimate is reported only when the
window holds at least ten oscillation periods, the simulated fit is good enough, the stiction
model explains clearly more than a linear valve, the optimum is well posed (not on the grid
edge, a compact low-error region, no distant S and no other delay fitting nearly as well), the
other valve model (He or Kano) agrees on S when it fits about as well, and the estimated valve
behaves as in a stick-slip cycle (stuck most of the time, about one slip per half-cycle, S most
of the OP travel per half-cycle, and on a self-regulating loop a slip jump: a deadband alone does
not sustain a limit cycle there).
Otherwise S and J are None and ``reasons`` says why.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from plantcheck.diagnosis.iir_kernels import (
    butterworth_sos,
    filter_rows,
    iir_filter,
    notch_sos,
    sos_filter,
)
from plantcheck.diagnosis.oscillation import faster_oscillation
from plantcheck.diagnosis.quantification_params import QuantificationParams
from plantcheck.diagnosis.quantification_rules import Evidence, refusals
from plantcheck.diagnosis.signal_tools import FloatArray, hann_power, moving_average
from plantcheck.diagnosis.valve_models import he_grid, kano_grid


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
    S_alternative: float | None = None
    model: str = "kano"
    stuck_fraction: float = 0.0
    op_excursion: float = 0.0
    external_period_s: float | None = None
    """Period (s) of the slow external oscillation notched out of OP and PV before the
    identification; None when OP showed none."""
    period_s: float | None = None
    """Oscillation period (s) the identification used: the given one, or a faster oscillation
    found beneath it."""
    surface: dict[str, FloatArray] = field(default_factory=dict, repr=False)
    reason_codes: list[str] = field(default_factory=list)
    """The failed rules' codes (``quantification_rules``), one per reason."""


class _ArxMoments:
    """Products of the delayed valve rows with the ARX regressors, for every delay at once.

    The regressor v(k − nk − i) of delay nk and lag i is the valve row shifted by o = nk + i.
    Its products with the PV regressors [−y(k−1) … −y(k−na), 1, y(k)] come from one matrix
    product for every shift needed; its products with the other valve regressors (shifts o
    and o + L, L < nb) from one pass over each row per L, corrected at the window's ends.
    """

    def __init__(
        self, v: FloatArray, y: FloatArray, na: int, nb: int, start: int, shifts: Sequence[int]
    ) -> None:
        n_p, n = v.shape
        self.start, self.rows = start, n_p
        yk = y[start:]
        ymat = np.column_stack(
            [-y[start - i : n - i] for i in range(1, na + 1)] + [np.ones(n - start)]
        )
        self.ygram = ymat.T @ ymat
        self.yb = ymat.T @ yk
        self.yy = float(yk @ yk)
        with_y = np.column_stack([ymat, yk])
        width = with_y.shape[1]
        self._col = {o: i * width for i, o in enumerate(shifts)}
        # the row shifted by o over k = start … n−1 is v[start − o : n − o]
        big = np.zeros((n, width * len(shifts)))
        for o, c in self._col.items():
            big[start - o : n - o, c : c + width] = with_y
        self._cross = v @ big
        # products of v(m) and v(m + L): the whole row, minus the first start − o2 terms and
        # the last o1 terms of the window (prefix and suffix sums, both short)
        top = max(shifts) + 1
        self._total, self._head, self._tail = [], [], []
        for lag in range(nb):
            lo, hi = v[:, : n - lag], v[:, lag:]
            self._total.append(np.einsum("pm,pm->p", lo, hi))
            head = np.zeros((n_p, start + 1))
            np.cumsum(lo[:, :start] * hi[:, :start], axis=1, out=head[:, 1:])
            tail = np.zeros((n_p, top + 1))
            np.cumsum((lo[:, ::-1][:, :top] * hi[:, ::-1][:, :top]), axis=1, out=tail[:, 1:])
            self._head.append(head)
            self._tail.append(tail)

    def cross(self, o: int) -> FloatArray:
        """(n_rows, na + 2): the row shifted by ``o`` times each PV regressor, then times y."""
        c = self._col[o]
        return self._cross[:, c : c + self.ygram.shape[0] + 1]

    def prod(self, o1: int, o2: int) -> FloatArray:
        """Per row: the row shifted by ``o1`` times the row shifted by ``o2`` (o2 >= o1)."""
        lag = o2 - o1
        out = self._total[lag] - self._head[lag][:, self.start - o2] - self._tail[lag][:, o1]
        return np.asarray(out, dtype=np.float64)


def _normal_equations(mom: _ArxMoments, delay: int, nb: int) -> tuple[FloatArray, FloatArray]:
    """Batched ARX normal equations (A θ = b) of one delay, solved for every valve row:
    the parameters and the residual energy per row."""
    q = mom.ygram.shape[0]
    dim = q + nb
    n_p = mom.rows
    a_mat = np.empty((n_p, dim, dim))
    a_mat[:, :q, :q] = mom.ygram
    b_vec = np.empty((n_p, dim))
    b_vec[:, :q] = mom.yb
    for i in range(nb):
        cross = mom.cross(delay + i)
        a_mat[:, :q, q + i] = cross[:, :q]
        a_mat[:, q + i, :q] = cross[:, :q]
        b_vec[:, q + i] = cross[:, q]
        for j in range(i, nb):
            a_mat[:, q + i, q + j] = a_mat[:, q + j, q + i] = mom.prod(delay + i, delay + j)
    a_mat += 1e-9 * np.eye(dim)[None, :, :] * np.trace(a_mat, axis1=1, axis2=2)[:, None, None]
    theta = np.linalg.solve(a_mat, b_vec[:, :, None])[:, :, 0]
    resid = mom.yy - np.sum(theta * b_vec, axis=1)
    return np.asarray(theta, dtype=np.float64), np.asarray(resid, dtype=np.float64)


def _stable_rows(a: FloatArray) -> np.ndarray:
    """Schur stability of each row's 1 + a1 z^-1 (+ a2 z^-2), closed form for orders 1 and 2."""
    if a.shape[1] == 2:
        return np.asarray(np.abs(a[:, 1]) < 1.0)
    if a.shape[1] == 3:
        return np.asarray((np.abs(a[:, 2]) < 1.0) & (np.abs(a[:, 1]) < 1.0 + a[:, 2]))
    return np.array([bool(np.all(np.abs(np.roots(r)) < 1.0)) for r in a])


def _simulation_errors(
    v: FloatArray, theta: FloatArray, delay: np.ndarray, na: int, y: FloatArray, warm: int
) -> FloatArray:
    """Output-error simulation of every row's ARX model (parameters [a1…a_na, c, b1…b_nb],
    delay in samples) from its valve row alone, starting at rest at the row's first value:
    the sum of squared errors against ``y`` after the first ``warm`` samples, per row."""
    n_p = v.shape[0]
    a = np.column_stack([np.ones(n_p), theta[:, :na]])
    b = theta[:, na + 1 :]
    # closed-loop least squares can return an unstable fit: reflect the poles inside the unit
    # circle (same spectrum shape) and simulate that model
    for i in np.flatnonzero(~_stable_rows(a)).tolist():
        roots = np.roots(a[i])
        roots = np.where(np.abs(roots) > 1.0, 1.0 / np.conj(roots), roots)
        roots = np.where(np.abs(roots) > 0.999, 0.999 * roots / np.abs(roots), roots)
        a[i] = np.real(np.poly(roots))
    # y minus the constant part of each simulation (its steady state from the first value)
    offset = (theta[:, na] + b.sum(axis=1) * v[:, 0]) / a.sum(axis=1)
    w = v - v[:, :1]
    sse = np.empty(n_p)
    n = v.shape[1]
    kernel = iir_filter()
    for i in range(n_p):
        d = int(delay[i])  # the delay as a shift of the input (warm >= d), not as zero taps
        err = y[warm:] - offset[i] - kernel(b[i], a[i], w[i, : n - d], -1)[warm - d :]
        sse[i] = err @ err
    return sse


def _fit_arx(
    v: FloatArray,
    y: FloatArray,
    max_delay: int,
    na: int = 2,
    nb: int = 2,
    delays: Sequence[int] | None = None,
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """ARX(na, nb, nk) for every row of ``v``: the delay nk in 1..max_delay with the smallest
    least-squares residual, then the model is simulated from v alone (output error).

    Returns (score = mean squared simulation error, fit %, delay) per row. ``delays``
    restricts the candidate delays (all of 1..max_delay by default).
    """
    n_p, n = v.shape
    start = max_delay + nb + na
    best_res = np.full(n_p, np.inf)
    theta = np.zeros((n_p, na + 1 + nb))
    delay = np.ones(n_p, dtype=np.intp)
    candidates = list(delays) if delays is not None else list(range(1, max_delay + 1))
    mom = _ArxMoments(v, y, na, nb, start, sorted({d + i for d in candidates for i in range(nb)}))
    for d in candidates:
        th, res = _normal_equations(mom, d, nb)
        better = res < best_res
        best_res = np.where(better, res, best_res)
        theta[better] = th[better]
        delay[better] = d
    # the simulation starts at rest: the first tenth of the window is its warm-up
    warm = max(start, n // 10)
    sse = _simulation_errors(v, theta, delay, na, y, warm)
    den = float(np.sum((y[warm:] - y[warm:].mean()) ** 2)) or 1.0
    score = sse / (n - warm)
    fit = 100.0 * (1.0 - np.sqrt(sse / den))
    return score, fit, delay


Prefilter = FloatArray
"""Second-order sections (scipy.signal.sosfilt)."""


def band_prefilter(f_lo: float, f_hi: float, highpass_order: int = 4) -> Prefilter:
    """Butterworth high-pass of ``highpass_order`` at ``f_lo`` and 2nd-order low-pass at
    ``f_hi`` (cycles per sample; no low-pass when ``f_hi`` reaches the Nyquist frequency), as
    second-order sections: a 4th-order edge a fifth of the oscillation frequency down is
    numerically fragile as one transfer function."""
    lo = min(max(2.0 * f_lo, 1e-4), 0.9)
    hi = 2.0 * f_hi
    sos = butterworth_sos(highpass_order, lo, btype="highpass")
    if lo * 1.5 < hi < 0.95:
        sos = np.vstack([sos, butterworth_sos(2, hi)])
    return sos


def slow_line(u: FloatArray, max_frequency: float, prominence: float = 30.0) -> float | None:
    """Frequency (cycles per sample) of the strongest spectral line of ``u`` between 2.5 cycles
    per window and ``max_frequency``, or None when its power (Hann-windowed periodogram) is
    less than ``prominence`` times the median power around it (0.6–1.6 × its frequency, the
    window's leakage bins left out).

    A sinusoidal load from elsewhere in the plant, slower than the loop's own cycle, shows as
    such a line in OP, which cancels it. The ARX model cannot explain it from the valve, and
    the high-pass prefilter lets part of it through (about a third at 0.15 × the loop's
    frequency): it biases the fit towards a wrong S or makes it too poor to report. Models
    with an additive disturbance give better stiction estimates when a disturbance acts
    together with stiction (Bacci di Capaci, Scali & Pannocchia 2016).
    """
    n = u.size
    freq = np.fft.rfftfreq(n)
    power = hann_power(u)
    band = np.flatnonzero((freq > 2.5 / n) & (freq < max_frequency))
    if band.size == 0:
        return None
    k = int(band[np.argmax(power[band])])
    around = (
        (freq > 0.6 * freq[k]) & (freq < 1.6 * freq[k]) & (np.abs(np.arange(freq.size) - k) > 2)
    )
    if not around.any() or power[k] < prominence * float(np.median(power[around])):
        return None
    return float(freq[k])


@dataclass(frozen=True)
class _Problem:
    """Filtered data and settings shared by every evaluation of one window."""

    u: FloatArray
    yf: FloatArray
    prefilter: Prefilter
    min_moves: int
    max_delay: int
    kano_phase: float
    """Where the first OP sample sits in the Kano valve's start band (0: at its top)."""


Model = Literal["kano", "he"]


def _valve_positions(
    u: FloatArray, model: Model, S: ArrayLike, J: ArrayLike, phase: ArrayLike = 0.5
) -> FloatArray:
    """Valve position of the model for every (S, J) pair, one row each. The He model
    (He et al. 2007) is parameterised by (S, J): f_s = (S + J)/2, f_d = (S − J)/2, and starts
    at u[0] + (phase − ½)·J: on a ramp it slips every J from where it started, so phases 0
    and 1 give the same slips after the first one. The Kano model (Kano et al. 2004) starts
    stuck, free outside the band u[0] + [(phase − 1), phase]·(S + J) (see kano_grid)."""
    s_arr = np.asarray(S, dtype=np.float64)
    j_arr = np.asarray(J, dtype=np.float64)
    if model == "kano":
        ph = np.asarray(phase, dtype=np.float64)
        return kano_grid(u, s_arr, j_arr, stuck=u[0] - s_arr + ph * (s_arr + j_arr))
    x0 = u[0] + (np.asarray(phase, dtype=np.float64) - 0.5) * j_arr
    return he_grid(u, (s_arr + j_arr) / 2.0, (s_arr - j_arr) / 2.0, x0=x0)


def _rows_from_start(v: FloatArray) -> FloatArray:
    """Each row of ``v`` minus its first value, as a new C-contiguous array. The grids return
    time along the first axis; one transposing pass over thousands of rows misses the cache at
    every element, a copy in tiles of 256 rows × 128 samples takes half the time."""
    if v.flags.c_contiguous:
        return np.asarray(v - v[:, :1], dtype=np.float64)
    out = np.empty(v.shape)
    rows, n = v.shape
    for i in range(0, rows, 256):
        for k in range(0, n, 128):
            out[i : i + 256, k : k + 128] = v[i : i + 256, k : k + 128]
    out -= out[:, :1].copy()
    return out


def _valves(
    prob: _Problem, model: Model, S: FloatArray, J: FloatArray, phase: ArrayLike = 0.5
) -> FloatArray:
    """Prefiltered valve trajectories for the (S, J) pairs; rows that barely move are NaN."""
    v = _valve_positions(prob.u, model, S, J, phase)
    vt = v.T  # time along the first axis: the grids' own memory layout, one pass
    moves = np.count_nonzero(vt[1:] != vt[:-1], axis=0)
    # the same linear filter on both sides keeps PV = G·v and removes slow load drift and noise
    vf = filter_rows(prob.prefilter, _rows_from_start(v))
    vf[moves < prob.min_moves] = np.nan
    return np.asarray(vf, dtype=np.float64)


def _scores(
    vf: FloatArray, prob: _Problem, order: int, delays: Sequence[int] | None = None
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Simulation error, fit (%) and delay per valve row; NaN rows get an infinite error."""
    ok = np.flatnonzero(~np.isnan(vf[:, 0]))
    score = np.full(vf.shape[0], np.inf)
    fit = np.full(vf.shape[0], -np.inf)
    delay = np.ones(vf.shape[0], dtype=np.intp)
    if ok.size:
        v = vf if ok.size == vf.shape[0] else vf[ok]
        score[ok], fit[ok], delay[ok] = _fit_arx(v, prob.yf, prob.max_delay, order, order, delays)
    return score, fit, delay


@dataclass(frozen=True)
class _Search:
    model: Model
    S: FloatArray
    J: FloatArray
    score: FloatArray
    s_best: float
    j_best: float
    best: float
    fit: float
    delay: int
    phase: float


def op_excursion(u: FloatArray, period_samples: float) -> float:
    """Median OP travel between consecutive reversals of the smoothed OP (% of OP).

    In a stick-slip limit cycle the controller output reverses soon after each slip, so its
    travel per half-cycle is S plus a small overshoot: the S grid is anchored on it.
    """
    width = max(1, round(period_samples / 20.0))
    us = moving_average(u, width)
    # reversals confirmed by hysteresis: OP must come back by a quarter of its 10–90 % range
    band = 0.25 * float(np.percentile(us, 90) - np.percentile(us, 10))
    turns: list[float] = []
    hi = lo = float(us[0])
    rising: bool | None = None
    for x in us.tolist():
        if rising is not False and x < hi - band:
            if rising:
                turns.append(hi)
            rising, lo = False, x
        elif rising is not True and x > lo + band:
            if rising is False:
                turns.append(lo)
            rising, hi = True, x
        hi = max(hi, x) if rising is not False else hi
        lo = min(lo, x) if rising is not True else lo
    if len(turns) < 3:
        return float(np.ptp(u))
    return float(np.median(np.abs(np.diff(turns))))


def _s_step(s_lo: float, s_hi: float, p: QuantificationParams) -> float:
    """The S grid's step, a ratio: its values are evenly spaced in log S."""
    return float((s_hi / s_lo) ** (1.0 / (p.n_s - 1)))


def _grid(
    s_lo: float, s_hi: float, p: QuantificationParams, phases: int
) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray]:
    """S, J and start phase of every grid point (J = 0 needs one phase only), and which points
    the delay scan uses (every ``delay_scan_s_stride``-th S, every ``delay_scan_ratio_step``-th
    J/S)."""
    s_vals = np.geomspace(s_lo, s_hi, p.n_s)
    rows = [(0.5, 0)] + [(k / phases, i) for i in range(1, p.n_ratio) for k in range(phases)]
    ph = np.array([r[0] for r in rows])
    ri = np.array([r[1] for r in rows])
    r_vals = np.linspace(0.0, p.max_ratio, p.n_ratio)[ri]
    s = np.repeat(s_vals, ph.size)
    thin_s = np.arange(p.n_s) % p.delay_scan_s_stride == 0
    thin = np.repeat(thin_s, ph.size) & np.tile(ri % p.delay_scan_ratio_step == 0, p.n_s)
    return s, s * np.tile(r_vals, p.n_s), np.tile(ph, p.n_s), thin


@dataclass(frozen=True)
class _Pick:
    """The best of a set of scored (S, J, phase) rows."""

    score: float
    S: float
    J: float
    fit: float
    delay: int
    phase: float


def _pick(
    prob: _Problem,
    model: Model,
    s: FloatArray,
    j: FloatArray,
    ph: FloatArray,
    order: int,
    delays: Sequence[int],
) -> _Pick:
    """Score the rows (S, J, start phase) with the given delays and return the best one."""
    score, fit, delay = _scores(_valves(prob, model, s, j, ph), prob, order, delays)
    k = int(np.argmin(score))
    return _Pick(
        float(score[k]), float(s[k]), float(j[k]), float(fit[k]), int(delay[k]), float(ph[k])
    )


def _score_of(pick: _Pick) -> float:
    """Sort key of a pick: its mean squared simulation error."""
    return pick.score


def _phase_polish_grid(
    s_c: FloatArray, j_c: FloatArray, score: FloatArray, step: float, p: QuantificationParams
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """He valve rows tried again from many start phases: the best pair (J > 0) of each of the
    ``he_polish_candidates`` best S values of the coarse grid, at S·step^(−½, 0, ½) and its J/S,
    from ``he_polish_phases`` phases over one slip."""
    ok = np.flatnonzero(np.isfinite(score) & (j_c > 0))
    ranked = ok[np.argsort(score[ok], kind="stable")]
    _, first = np.unique(s_c[ranked], return_index=True)
    picked = ranked[np.sort(first)][: p.he_polish_candidates]
    shape = (picked.size, 3, p.he_polish_phases)
    s = s_c[picked][:, None, None] * (step ** np.array([-0.5, 0.0, 0.5]))[None, :, None]
    s_all = np.broadcast_to(s, shape)
    j_all = s_all * (j_c[picked] / s_c[picked])[:, None, None]
    ph = np.broadcast_to(np.arange(p.he_polish_phases) / p.he_polish_phases, shape)
    return s_all.ravel(), j_all.ravel(), ph.ravel()


def _search(
    prob: _Problem, model: Model, s_lo: float, s_hi: float, order: int, p: QuantificationParams
) -> _Search:
    """Coarse (S, J) grid, then a finer grid around the best pair; for the He structure each
    pair from ``he_phases`` starting positions (the valve never forgets where it started), then
    the best few S values from many more (the phase polish)."""
    phases = p.he_phases if model == "he" else 1
    s_c, j_c, ph_c, thin = _grid(s_lo, s_hi, p, phases)
    if model == "kano":
        ph_c[:] = prob.kano_phase  # every Kano row starts from the window's start band
    step = _s_step(s_lo, s_hi, p)
    # the delay scan's subset first: it and the other rows are then views of one array
    rows = np.concatenate([np.flatnonzero(thin), np.flatnonzero(~thin)])
    n_thin = int(np.count_nonzero(thin))
    vf = _valves(prob, model, s_c[rows], j_c[rows], ph_c[rows])
    # The delay belongs to the process, not to (S, J), but S and the delay trade off (a smaller
    # S slips earlier, a longer delay shifts the response back). Every delay is scanned on a
    # thin subset of the grid (every other S, a few J/S), and the full grid then chooses among
    # the delays of the subset's good pairs, ± one sample.
    t_score, t_fit, t_delay = _scores(vf[:n_thin], prob, order)
    good = np.isfinite(t_score) & (t_score <= p.delay_scan_tol * np.min(t_score, initial=np.inf))
    chosen = np.unique(t_delay[good]) if good.any() else np.array([1])
    near = sorted(
        {int(d + k) for d in chosen for k in (-1, 0, 1)} & set(range(1, prob.max_delay + 1))
    )
    # a subset row whose best delay is among these already has its result
    redo = np.flatnonzero(np.isfinite(t_score) & ~np.isin(t_delay, near))
    if redo.size:
        t_score[redo], t_fit[redo], t_delay[redo] = _scores(vf[redo], prob, order, near)
    r_score, r_fit, r_delay = _scores(vf[n_thin:], prob, order, near)
    score, fit, delay = np.empty(rows.size), np.empty(rows.size), np.empty(rows.size, np.intp)
    score[rows] = np.concatenate([t_score, r_score])
    fit[rows] = np.concatenate([t_fit, r_fit])
    delay[rows] = np.concatenate([t_delay, r_delay])
    i = int(np.argmin(score))
    best = _Pick(
        float(score[i]), float(s_c[i]), float(j_c[i]), float(fit[i]), int(delay[i]), float(ph_c[i])
    )
    ph_f = np.array([best.phase])
    if phases > 1:
        # A He valve's slips stay where its start put them (each slip lands where the last one
        # put it), so a He fit is sharp in the start phase (about a tenth of J wide in the
        # benchmark loops) and in S: the coarse phases, J/he_phases apart, often miss it.
        s_p, j_p, ph_p = _phase_polish_grid(s_c, j_c, score, step, p)
        if s_p.size:
            best = min(best, _pick(prob, model, s_p, j_p, ph_p, order, near), key=_score_of)
        ph_f = best.phase + np.array([-0.5, 0.0, 0.5]) / p.he_polish_phases
    s_f = np.geomspace(best.S / step, best.S * step, p.refine)
    r_best = best.J / best.S if best.S > 0 else 0.0
    dr = p.max_ratio / (p.n_ratio - 1)
    r_f = np.linspace(max(0.0, r_best - dr), min(p.max_ratio, r_best + dr), p.refine)
    sg, rg, pg = np.meshgrid(s_f, r_f, ph_f, indexing="ij")
    fine = _pick(prob, model, sg.ravel(), (sg * rg).ravel(), pg.ravel(), order, near)
    best = min(best, fine, key=_score_of)
    # J polish: every J/S at S*, a He valve from many starts, at the delay found. The grid's
    # J/S and starts are coarse and a He fit is sharp in the start at each J, so the local
    # refinement can keep a J that fits worse than another one from that J's own best start.
    r_j = np.linspace(0.0, p.max_ratio, p.j_polish_ratios)
    starts = (
        np.arange(p.j_polish_phases) / p.j_polish_phases if phases > 1 else np.array([best.phase])
    )
    j_pick = _pick(
        prob,
        model,
        np.full(r_j.size * starts.size, best.S),
        best.S * np.repeat(r_j, starts.size),
        np.tile(starts, r_j.size),
        order,
        [best.delay],
    )
    best = min(best, j_pick, key=_score_of)
    return _Search(
        model, s_c, j_c, score, best.S, best.J, best.score, best.fit, best.delay, best.phase
    )


def quantify_stiction(
    op: FloatArray,
    pv: FloatArray,
    ts: float,
    period_s: float | None = None,
    params: QuantificationParams | None = None,
    integrating: bool | None = None,
) -> QuantificationResult:
    """Estimate S and J (% of valve travel) from OP and PV by Hammerstein identification.

    Parameters
    ----------
    op, pv:
        Controller output (% 0–100) and process variable of an oscillating, constant-SP,
        automatic-mode window without gaps.
    ts:
        Sample time, s.
    period_s:
        Oscillation period, s: sets the prefilter band and bounds the delay search. When a
        faster oscillation is found beneath it (``separate_oscillations``), the valve is
        identified on that one and the given one is notched out as external.
    integrating:
        Whether the process integrates (level loops); False enables rule 9 (a deadband alone
        does not sustain a limit cycle in a self-regulating loop); None when unknown.

    Raises
    ------
    ValueError
        ``op`` and ``pv`` of different shapes, or with NaN/inf (a flat OP is not an error: the
        estimate is null with the reason).
    """
    p = params or QuantificationParams()
    u = np.asarray(op, dtype=np.float64)
    y = np.asarray(pv, dtype=np.float64)
    if u.ndim != 1 or u.shape != y.shape:
        raise ValueError(f"op and pv must be 1-D and of equal length (got {u.shape}, {y.shape})")
    if not (np.isfinite(u).all() and np.isfinite(y).all()):
        raise ValueError("op and pv must be finite: fill or cut the gaps (NaN) first")
    if u.size < 2 or np.ptp(u) == 0.0:
        return QuantificationResult(
            S=None,
            J=None,
            reliable=False,
            reasons=["OP does not move: no valve travel to identify"],
            S_best=0.0,
            J_best=0.0,
            fit=-math.inf,
            score_ratio=0.0,
            delay_samples=0,
        )
    u = u - u.mean()
    y = y - y.mean()
    dominant_s: float | None = None
    if period_s and p.separate_oscillations:
        # a stick-slip cycle under a slower, stronger external oscillation: the detection
        # reports the external one; the valve is identified at the loop's own cycle
        fast = faster_oscillation(y, ts, period_s)
        if fast is not None and fast.period_s is not None:
            dominant_s, period_s = period_s, fast.period_s
    period_samples = period_s / ts if period_s else y.size / 10.0
    max_delay = int(min(max(2, p.max_delay_fraction * period_samples), 60))
    pf = band_prefilter(
        p.highpass_fraction / period_samples,
        p.lowpass_multiple / period_samples,
        p.highpass_order,
    )
    # a slow external oscillation is notched out of both sides (the valve rows and PV)
    line = slow_line(u, p.line_max_fraction / period_samples, p.line_prominence)
    if line is None and dominant_s is not None:
        # the detected oscillation was not the valve's cycle: it is the external one
        line = ts / dominant_s
    if line is not None:
        pf = np.vstack([pf, notch_sos(line, p.notch_q)])
    # The Kano valve starts stuck with its break band at the first sample's edge facing the
    # bulk of the OP: it breaks free the first time the OP passes u0 that way, and so never
    # locks (from BDSIM's centred band a valve with S + J above the OP range never moves).
    kano_phase = 0.0 if u[0] <= float(np.median(u)) else 1.0
    prob = _Problem(u, sos_filter(pf, y - y[0]), pf, p.min_moves, max_delay, kano_phase)
    s_max = p.s_max_fraction * float(np.ptp(u))
    excursion = op_excursion(u, period_samples)
    s_hi = min(s_max, p.grid_high * excursion)
    s_lo = min(p.grid_low * excursion, 0.5 * s_hi)
    kano_fit = _search(prob, "kano", s_lo, s_hi, 2, p)
    # the He structure: fewer J/S values, each from he_phases starting positions
    he_fit = _search(prob, "he", s_lo, s_hi, 2, replace(p, n_ratio=p.he_n_ratio))
    main, other = (kano_fit, he_fit) if kano_fit.best <= he_fit.best else (he_fit, kano_fit)
    # rule 3 reference: a deadband of 2 % of the grid range. With v = OP exactly the closed-
    # loop regressors are collinear (OP is a linear function of past PV) and the fit is
    # meaningless; a tiny deadband removes the collinearity without modelling stiction.
    vref = _valves(
        prob, "kano", np.array([p.reference_fraction * s_max]), np.array([0.0]), kano_phase
    )
    score_lin = float(_scores(vref, prob, 2)[0][0])
    ratio = main.best / score_lin if math.isfinite(score_lin) and score_lin > 0 else 0.0
    # rule 4b's line: S along the estimate's J/S with every delay free (see its rule)
    s_line = line_score = np.zeros(0)
    if main.s_best > 0 and math.isfinite(main.best):
        ratio_j = main.j_best / main.s_best
        n_ph = p.he_phases if main.model == "he" and ratio_j > 0 else 1
        # a He valve's start phase belongs to (S, J): every phase is tried along the line
        s_line = np.repeat(main.s_best * np.array(p.tradeoff_factors), n_ph)
        ph_line = np.tile(np.arange(n_ph) / n_ph, len(p.tradeoff_factors))
        if main.model == "kano":
            ph_line[:] = prob.kano_phase
        line_score, _, _ = _scores(
            _valves(prob, main.model, s_line, ratio_j * s_line, ph_line),
            prob,
            2,
            range(1, max_delay + 1),
        )
    ev = Evidence(
        params=p,
        integrating=integrating,
        cycles=u.size / period_samples,
        period_samples=period_samples,
        n_samples=u.size,
        model=main.model,
        best=main.best,
        fit=main.fit,
        s_best=main.s_best,
        j_best=main.j_best,
        S=main.S,
        score=main.score,
        other_model=other.model,
        other_best=other.best,
        other_s_best=other.s_best,
        score_ratio=ratio,
        grid_top=s_hi / _s_step(s_lo, s_hi, p),
        tradeoff_S=s_line,
        tradeoff_score=line_score,
        valve=_valve_positions(u, main.model, [main.s_best], [main.j_best], main.phase)[0],
        excursion=excursion,
    )
    refused = refusals(ev)
    reasons = [r.text for r in refused]
    stuck = ev.stuck_fraction
    reliable = not reasons
    return QuantificationResult(
        S=main.s_best if reliable else None,
        J=main.j_best if reliable else None,
        reliable=reliable,
        reasons=reasons,
        reason_codes=[r.code for r in refused],
        S_best=main.s_best,
        J_best=main.j_best,
        fit=main.fit,
        score_ratio=ratio,
        delay_samples=main.delay,
        S_alternative=other.s_best,
        model=main.model,
        stuck_fraction=stuck,
        op_excursion=excursion,
        external_period_s=ts / line if line is not None else None,
        period_s=period_s,
        surface={"S": main.S, "J": main.J, "score": main.score},
    )
