"""Horch's stiction tests (methods.md §4.4; thesis §2.4).

- Cross-correlation OP–PV (Horch 1999, CEP 7:1221) for self-regulating loops: an odd CCF
  (r(0) ≈ 0, extrema near ±Tp/4) indicates stiction, an even one (extremum at lag 0) not.
  The odd/even reading is quantified by Δφ = π·|d_r − d_l|/(d_r + d_l) from the first zero
  crossings either side of lag 0 [M].
- Histogram test for integrating loops (Horch 2000/2002): the distribution of the second
  difference of the filtered PV. Following the thesis text (Bacci di Capaci 2016, §2.4):
  with stiction the PV is piecewise linear, its second difference is near zero with rare
  spikes (a single peak, heavy tails); without stiction the PV is sinusoidal and the second
  difference has the two-peaked arcsine ("camel") distribution. (methods.md §4.4 states the
  opposite mapping; the thesis and the waveform argument above agree with each other.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from plantcheck.diagnosis.signal_tools import (
    FloatArray,
    detrend,
    fft_ccf,
    interpolated_zero_crossings,
    moving_average,
)
from plantcheck.diagnosis.stiction_verdict import StictionTestResult, Verdict


@dataclass(frozen=True)
class HorchParams:
    """Thresholds of Horch's tests."""

    ccf_odd: float = 2 * math.pi / 3
    """Δφ at or above this -> odd CCF -> stiction [M]."""
    ccf_even: float = math.pi / 3
    """Δφ at or below this -> even CCF -> no stiction [M]."""
    max_lag_periods: float = 1.5
    """CCF computed up to this many oscillation periods (methods §4.4)."""
    hist_bimodal: float = 0.7
    """Mixture half-separation m (in σ) at or above which the histogram is two-peaked [R]."""
    hist_peaked_kurtosis: float = 0.4
    """Excess kurtosis above which a single-peaked histogram counts as stiction [R]."""
    hist_scale_per_period: float = 10.0
    """The second difference is taken over 1/this of the oscillation period [R]."""


def phase_index(ccf: FloatArray, lags: np.ndarray) -> tuple[float, float, float] | None:
    """Δφ (rad) and the distances (samples) to the first CCF zero crossing left and right of 0."""
    zero = int(np.flatnonzero(lags == 0)[0])
    right = interpolated_zero_crossings(ccf[zero:])
    left = interpolated_zero_crossings(ccf[: zero + 1][::-1])
    if right.size == 0 or left.size == 0:
        return None
    d_r = float(right[0])
    d_l = float(left[0])
    if d_r + d_l <= 0:
        return None
    return math.pi * abs(d_r - d_l) / (d_r + d_l), d_l, d_r


def horch_ccf(
    op: FloatArray,
    pv: FloatArray,
    ts: float,
    period_s: float,
    params: HorchParams | None = None,
) -> StictionTestResult:
    """Horch (1999) OP–PV cross-correlation test; ``label``: ``odd``, ``even`` or ``undecided``."""
    p = params or HorchParams()
    width = max(1, round(period_s / ts / 20.0))
    u = moving_average(detrend(op), width)
    y = moving_average(detrend(pv), width)
    max_lag = min(int(p.max_lag_periods * period_s / ts), op.size // 2)
    if max_lag < 2:
        return StictionTestResult("cross_correlation", None, "undecided", "period too short")
    lags, ccf = fft_ccf(u, y, max_lag)
    res = phase_index(ccf, lags)
    if res is None:
        return StictionTestResult(
            "cross_correlation", None, "undecided", "no CCF zero crossing", "undecided"
        )
    dphi, d_l, d_r = res
    verdict: Verdict
    if dphi >= p.ccf_odd:
        verdict, label = "stiction", "odd"
    elif dphi <= p.ccf_even:
        verdict, label = "no_stiction", "even"
    else:
        verdict, label = "undecided", "undecided"
    detail = f"Δφ = {dphi:.2f} rad, zero crossings at −{d_l * ts:.1f} s / +{d_r * ts:.1f} s"
    return StictionTestResult("cross_correlation", dphi, verdict, detail, label)


def _mixture_separation(z: FloatArray) -> float:
    """Best half-separation m of the unit-variance mixture ½N(−m, 1−m²) + ½N(m, 1−m²)."""
    m = np.linspace(0.0, 0.95, 20)[:, None]
    s2 = 1.0 - m**2
    zz = z[None, :]
    like = 0.5 * (np.exp(-((zz - m) ** 2) / (2 * s2)) + np.exp(-((zz + m) ** 2) / (2 * s2)))
    loglik = np.sum(np.log(like / np.sqrt(2 * np.pi * s2) + 1e-300), axis=1)
    return float(m[int(np.argmax(loglik)), 0])


def horch_histogram(
    pv: FloatArray, ts: float, period_s: float, params: HorchParams | None = None
) -> StictionTestResult:
    """Horch's second-difference histogram test for integrating (level) loops.

    The PV is smoothed and differenced twice over a tenth of the oscillation period, standardised;
    a clearly two-peaked distribution means no stiction, a single sharp peak with heavy tails
    means stiction. ``value`` is the fitted mixture half-separation m (units of σ).
    """
    p = params or HorchParams()
    # Second difference at the scale of a tenth of the period, on the PV smoothed over the same
    # scale: sample-to-sample second differences only show the measurement noise.
    lag = max(1, round(period_s / ts / p.hist_scale_per_period))
    y = moving_average(detrend(pv), lag)[lag:-lag] if pv.size > 4 * lag + 50 else detrend(pv)
    d2 = y[2 * lag :] - 2.0 * y[lag:-lag] + y[: -2 * lag] if y.size > 2 * lag else np.empty(0)
    sd = float(d2.std())
    if d2.size < 50 or sd == 0:
        return StictionTestResult("histogram", None, "undecided", "too few samples")
    z = (d2 - d2.mean()) / sd
    if z.size > 20000:
        z = z[:: z.size // 20000 + 1]
    m = _mixture_separation(z)
    kurt = float(np.mean(z**4) - 3.0)
    verdict: Verdict
    if m >= p.hist_bimodal:
        verdict = "no_stiction"
    elif kurt >= p.hist_peaked_kurtosis:
        verdict = "stiction"
    else:
        verdict = "undecided"
    detail = f"mixture separation {m:.2f} σ, excess kurtosis {kurt:.2f}"
    return StictionTestResult("histogram", m, verdict, detail)
