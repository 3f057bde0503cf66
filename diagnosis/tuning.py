"""Controller-tuning indices (methods.md §3.2–§3.3).

- ``identify_pi``: the PI controller's gain and integral time estimated from routine data by
  least squares on the velocity form ΔOP = Kc·Δe + (Kc·Ts/Ti)·e (OP is an exact function of
  the measured error, so the regression is well posed when the loop is in automatic). The
  sign of Kc gives the sign of the process gain (a stable loop has Kc·Kp > 0).
- ``idle_index``: Hägglund (1999, CEP 7:1505) idle index I_i = (t_pos − t_neg)/(t_pos + t_neg)
  on filtered increments of OP and PV; I_i near +1 means a sluggish loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from plantcheck.diagnosis.signal_tools import (
    FloatArray,
    block_means,
    fft_acf,
    first_order_lag,
    median,
    noise_sigma,
)


@dataclass(frozen=True)
class TuningParams:
    """Thresholds of the tuning indices."""

    idle_limit: float = 0.0
    """Idle index above this -> sluggish. Hägglund (1999/2005) suggests 0.4 [M]; with increments
    filtered over 0.5·Ti, 0 recognised 64 % of the generated sluggish loops and flagged none of
    the healthy ones, against 24 % at 0.4 (benchmarks/diagnosis_accuracy.py) [calibrated]."""
    step_slowness_limit: float = 3.0
    """Set-point step response: closed-loop time constant above this many dead times ->
    sluggish (``step_response.step_slowness``). SIMC tuning answers in about one dead time
    (Skogestad 2003); generated windows with steps (``simulator/plant_windows.py``): healthy
    loops 0.6-2.4, sticky ones 0.5-2.7, sluggish ones 3.2-350 [R]."""
    step_overshoot_limit: float = 0.5
    """Set-point steps too close together for the oscillation tests: responses that overshoot
    by at most this share of the step (median) are ok, beyond it undecided. Generated windows
    (10-90 %): healthy 0.07-0.35, aggressive 0.61-1.0, sticky and disturbed 0.16-1.1 [R]."""
    load_recovery_limit: float = 3.0
    """Load responses: recovery (peak to 37 %) above this many times the departure (onset to
    peak) -> sluggish, where no set-point step says otherwise (``load_recovery``). Generated
    windows of self-regulating loops (``simulator/plant_windows.py``, seeds 1-2, 10-90 %):
    healthy 0.8-1.8, sticky 0.3-0.9, aggressive or disturbed 0.7-1.0, sluggish 2.6-8.1; above
    3: 34 of the 40 sluggish windows with a load response read, none of the healthy, sticky,
    aggressive or disturbed ones (3 saturated ones, which the window check decides first) [R]."""
    creep_max_jump: float = 0.6
    """A set-point step answered with a creep (``step_response.StepResponse.creeps``): the PV
    rises from 20 % to 63 % of the step (or to the next step) without moving more than this
    share of it within 8 samples, OP pushing on past its kick, slower than
    ``step_slowness_limit``. Where every step of a window creeps, one of them to its 63 %
    point, and no stick-slip event breaks away while the PV settles after one, the events are
    set aside as load changes a sluggish loop leaves standing. Generated windows (seeds 1-2):
    4 sluggish plant windows and 4 healthy short-window loops no longer read stiction at
    0.5-0.8, no sticky window is lost; at 0.3-0.4 one healthy flow fewer, at 0.25 two more, at
    1.0 one sticky plant window is lost. Sticky valves under a detuned PI (gain × 0.2-0.5,
    integral time × 2-5; 288 generated windows) creep through their steps too: 6 of them read
    sluggish by this rule [R]."""
    idle_min_samples: int = 50
    """Fewest informative samples (both increments beyond the dead zone) for an idle index."""
    idle_filter_ti: float = 0.5
    """Increment filter time constant as a fraction of the identified Ti [R]."""
    idle_filter_correlation: float = 0.5
    """... and at least this fraction of the control error's correlation time (the lag at which
    its ACF falls to 1/e). A low-gain loop recovers over many integral times; filtered over
    0.5·Ti only, the increments read the PV noise that the proportional action copies into OP,
    and the index turns negative. 0.5 found 60 % of the generated sluggish loops without a set-
    point step (50 % before) and flagged no healthy one; 1.0 flagged 6 of 108 [calibrated]."""
    idle_deadzone: float = 0.2
    """Increments smaller than this fraction of their std are ignored [R]."""
    pi_min_fit: float = 0.5
    """R² of the PI regression below which Kc and Ti are not trusted [R]."""


def correlation_time(x: FloatArray, ts: float) -> float:
    """Lag (s) at which the autocorrelation of ``x`` first falls below 1/e; the
    record's length when it never does: the time scale of the loop's excursions."""
    acf = fft_acf(x, max_lag=x.size)
    below = np.flatnonzero(acf < np.exp(-1.0))
    return float(below[0] if below.size else x.size) * ts


def idle_filter_s(e: FloatArray, ts: float, ti_s: float | None, params: TuningParams) -> float:
    """Filter time constant (s) of the idle index: ``idle_filter_ti`` × Ti (10 samples without
    a trusted Ti), at least ``idle_filter_correlation`` × the error's correlation time."""
    base = params.idle_filter_ti * ti_s if ti_s else 10.0 * ts
    return max(base, params.idle_filter_correlation * correlation_time(e, ts))


@dataclass(frozen=True)
class PIEstimate:
    """Identified PI controller: Kc in %OP per PV unit, Ti in s, R² of the regression."""

    kc: float
    ti_s: float | None
    fit: float

    @property
    def gain_sign(self) -> int:
        """Sign of the process gain implied by the controller action (+1 reverse acting)."""
        return 1 if self.kc >= 0 else -1


def identify_pi(
    op: FloatArray, pv: FloatArray, sp: FloatArray, ts: float, block: int = 5
) -> PIEstimate:
    """PI identification (``_identify_pi``); where the regression is poor and its
    proportional and integral gains disagree in sign, which no PI controller does, once more
    on means over ``block`` samples. A historian that compresses the PV holds it until it
    has moved by its dead band, so the recorded error steps where the controller saw it
    creep: sample by sample the proportional term then fits the wrong way round and reads the
    process gain's sign inverted (19 of 288 short-window cases, 18 of them compressed, one
    coarsely quantised); the block means average the holds out and read all 19 right."""
    pi = _identify_pi(op, pv, sp, ts)
    if pi.ti_s is not None or pi.fit >= BLOCK_FIT or op.size < 20 * block:
        return pi
    coarse = _identify_pi(
        block_means(op, block), block_means(pv, block), block_means(sp, block), ts * block
    )
    return coarse if coarse.ti_s is not None else pi


BLOCK_FIT = 0.9
"""R² at or above which a sample-by-sample PI regression is trusted as it is."""


def _identify_pi(op: FloatArray, pv: FloatArray, sp: FloatArray, ts: float) -> PIEstimate:
    """Least-squares PI identification from OP, PV, SP.

    ΔOP(k) = a·e(k) + b·e(k−1) + c covers both discrete PI forms (integral on e(k) or on
    e(k−1)); then Kc·Ts/Ti = a + b and Kc = (a − b)/2 (the Tustin midpoint of the two).
    """
    e = sp - pv
    d_op = np.diff(op)
    reg = np.column_stack([e[1:], e[:-1], np.ones(d_op.size)])
    coef, *_ = np.linalg.lstsq(reg, d_op, rcond=None)
    resid = d_op - reg @ coef
    var = float(np.var(d_op))
    fit = 1.0 - float(np.var(resid)) / var if var > 0 else 0.0
    kc_a, ti_a = pi_settings(np.asarray(coef, dtype=np.float64), ts)
    kc, ki = float(kc_a), float(coef[0] + coef[1])
    ti = float(ti_a) if np.isfinite(ti_a) else None
    if ti is None and ki != 0:
        # Integral action alone still gives the controller direction: ΔOP ∝ e.
        kc = math.copysign(abs(kc) or 1e-12, ki)
    return PIEstimate(kc, ti, max(fit, 0.0))


def pi_settings(coef: FloatArray, ts: float) -> tuple[FloatArray, FloatArray]:
    """Kc and Ti (s; NaN where no PI controller has them: no integral action, or the two
    gains of opposite sign) from the regression coefficients a, b of ΔOP(k) = a·e(k) +
    b·e(k−1) + c (the last axis of ``coef``; ``_identify_pi``): Kc·Ts/Ti = a + b and
    Kc = (a − b)/2."""
    a, b = coef[..., 0], coef[..., 1]
    ki = a + b
    kc = (a - b) / 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        ti = np.where((ki != 0) & (kc * ki > 0), kc * ts / ki, np.nan)
    return kc, ti


def lowpass(x: FloatArray, ts: float, tf_s: float) -> FloatArray:
    """First-order low-pass with time constant ``tf_s`` seconds (exact discretisation)."""
    if tf_s <= 0:
        return x
    return first_order_lag(x, math.exp(-ts / tf_s))


def idle_index(
    op: FloatArray,
    pv: FloatArray,
    ts: float,
    gain_sign: int = 1,
    filter_s: float | None = None,
    params: TuningParams | None = None,
) -> float | None:
    """Hägglund idle index I_i ∈ [−1, 1] (sluggish when close to +1); None if not informative.

    Only samples where the filtered PV is away from its mean by more than 2σ of the noise and
    both increments exceed the dead zone are counted (the index is meaningful only while the
    loop recovers from a load, Hägglund 1999).
    """
    p = params or TuningParams()
    tf = filter_s if filter_s is not None else 10.0 * ts
    u = lowpass(op, ts, tf)
    y = lowpass(pv, ts, tf)
    du = np.diff(u)
    dy = np.diff(y)
    sn = noise_sigma(pv)
    away = np.abs(y[1:] - median(y)) > 2.0 * sn
    dz_u = p.idle_deadzone * float(np.std(du))
    dz_y = p.idle_deadzone * float(np.std(dy))
    use = away & (np.abs(du) > dz_u) & (np.abs(dy) > dz_y)
    if int(use.sum()) < p.idle_min_samples:
        return None
    prod = np.sign(du[use] * dy[use])
    t_pos = float(np.sum(prod > 0))
    t_neg = float(np.sum(prod < 0))
    return gain_sign * (t_pos - t_neg) / (t_pos + t_neg)
