"""Waveform-shape stiction tests on half-cycles (methods.md §4.1, §4.2, §4.6).

- Relay technique, Rossi & Scali (2005, JPC 15:505): PV half-cycles fitted by a sinusoid and
  by the first-order response to a relay (square-wave) input; SI = (E_sin − E_rel)/(E_sin + E_rel).
- Curve fitting, He, Wang, Pottmann & Qin (2007, IECR 46:4549): half-cycles of the signal after
  the first integrator (OP for self-regulating loops, PV for integrating ones) fitted by a
  sinusoid and a triangle (apex position free); SI = MSE_sin/(MSE_sin + MSE_tri).
- Area ratio, Singhal & Salsbury (2005, JPC 15:371): R = mean A1/A2, areas of |e| before and
  after the half-cycle peak.

Half-cycles are RMS-normalised so that large cycles do not dominate (methods §4.1).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from plantcheck.diagnosis.signal_tools import (
    FloatArray,
    HalfCycles,
    first_peaks,
    fit_error_to_templates,
    half_cycles,
    mean,
    unit_grid,
)
from plantcheck.diagnosis.stiction_verdict import StictionTestResult, three_way

N_POINTS = 32


@dataclass(frozen=True)
class ShapeParams:
    """Thresholds of the shape tests (methods.md §10)."""

    relay_yes: float = 0.2
    """Relay SI at or above this -> stiction (±0.21 recalled [M]; ±0.2 maps He's 0.4/0.6)."""
    relay_no: float = -0.2
    """Relay SI at or below this -> no stiction [M]."""
    curvefit_yes: float = 0.6
    """He SI at or above this -> stiction ([V] controllerPlotFcn3.m)."""
    curvefit_no: float = 0.4
    """He SI at or below this -> no stiction ([V])."""
    curvefit_yes_integrating: float = 0.65
    """He SI at or above this -> stiction on a level loop, whose PV the fit reads: a level
    integrates the flow, so even a linear cycle's PV leans toward the triangle. Generated plant
    windows (seeds 1-4, three process tables) and the matrix: aggressive level loops read up
    to 0.64, sticky ones whose Horch histogram agrees 0.67 and more (one at 0.665); the same
    verdicts from 0.65 to 0.66, at 0.67 a sticky window is lost [R]."""
    area_yes: float = 1.2
    """Singhal–Salsbury R above this -> stiction ([R] margin around 1)."""
    area_no: float = 0.9
    """R below this -> no stiction ([R])."""
    min_half_cycles: int = 4
    """Fewest usable half-cycles for any shape verdict [R]."""
    min_half_samples: int = 5
    """Half-cycles shorter than this are skipped (methods §4.1)."""
    curvefit_min_half_samples: int = 10
    """Half-cycles shorter than this are skipped by the curve fit (He et al. 2007). Sampled at
    fewer points a half sine and its best triangle differ by less than the sampling itself: a
    fast linear oscillation (an aggressive loop at ~10 samples per period) read as triangular in
    most windows. [R: generated cases seeds 1-5 and ISDB: no verdict lost, 2 fewer false
    stiction]"""


@cache
def sine_template() -> FloatArray:
    """Positive half sine on normalised time [0, 1], shape (1, N_POINTS)."""
    return np.sin(np.pi * unit_grid(N_POINTS))[None, :]


@cache
def relay_templates(n_tau: int = 24) -> FloatArray:
    """First-order responses to a relay half-cycle, τ/D on a log grid 0.02…5 (methods §4.1).

    y = 1 − e^{−s/τ} up to the switch s_w = 1 + τ·ln((1 + e^{−1/τ})/2), then
    (y(s_w) + 1)·e^{−(s − s_w)/τ} − 1, which returns to zero at s = 1.
    """
    s = unit_grid(N_POINTS)[None, :]
    tau = np.logspace(np.log10(0.02), np.log10(5.0), n_tau)[:, None]
    s_w = 1.0 + tau * np.log((1.0 + np.exp(-1.0 / tau)) / 2.0)
    rise = 1.0 - np.exp(-s / tau)
    y_w = 1.0 - np.exp(-s_w / tau)
    fall = (y_w + 1.0) * np.exp(-(s - s_w) / tau) - 1.0
    out = np.where(s <= s_w, rise, fall)
    out[:, -1] = 0.0
    return np.asarray(out, dtype=np.float64)


@cache
def triangle_templates(n_apex: int = 19) -> FloatArray:
    """Triangles with the apex at 0.05…0.95 of the half-cycle (He et al. 2007)."""
    s = unit_grid(N_POINTS)[None, :]
    apex = np.linspace(0.05, 0.95, n_apex)[:, None]
    return np.asarray(np.where(s <= apex, s / apex, (1.0 - s) / (1.0 - apex)), dtype=np.float64)


def significant_half_cycles(
    x: FloatArray, ts: float, band: float, min_amplitude: float, min_samples: int = 5
) -> HalfCycles:
    """Half-cycles of mean-removed ``x`` whose peak exceeds ``min_amplitude`` (signal units)."""
    hc = half_cycles(x - mean(x), ts, band=band, min_samples=min_samples, n_points=N_POINTS)
    keep = hc.peak >= min_amplitude
    return HalfCycles(hc.shapes[keep], hc.starts[keep], hc.stops[keep], hc.iae[keep], hc.peak[keep])


def relay_index(hc: HalfCycles, params: ShapeParams | None = None) -> StictionTestResult:
    """Rossi & Scali (2005) relay stiction index on PV half-cycles, SI ∈ [−1, 1]."""
    p = params or ShapeParams()
    if hc.count < p.min_half_cycles:
        return StictionTestResult("relay", None, "undecided", f"{hc.count} half-cycles")
    e_sin = float(np.mean(fit_error_to_templates(hc.shapes, sine_template())))
    e_rel = float(np.mean(fit_error_to_templates(hc.shapes, relay_templates())))
    si = (e_sin - e_rel) / (e_sin + e_rel) if e_sin + e_rel > 0 else 0.0
    return StictionTestResult(
        "relay", si, three_way(si, p.relay_yes, p.relay_no), f"{hc.count} half-cycles"
    )


def curve_fit_index(hc: HalfCycles, params: ShapeParams | None = None) -> StictionTestResult:
    """He et al. (2007) sine/triangle curve-fitting index, SI ∈ [0, 1]."""
    p = params or ShapeParams()
    if hc.count < p.min_half_cycles:
        return StictionTestResult("curve_fit", None, "undecided", f"{hc.count} half-cycles")
    mse_sin = float(np.mean(fit_error_to_templates(hc.shapes, sine_template())))
    mse_tri = float(np.mean(fit_error_to_templates(hc.shapes, triangle_templates())))
    si = mse_sin / (mse_sin + mse_tri) if mse_sin + mse_tri > 0 else 0.5
    return StictionTestResult(
        "curve_fit", si, three_way(si, p.curvefit_yes, p.curvefit_no), f"{hc.count} half-cycles"
    )


def area_ratio(
    x: FloatArray, hc: HalfCycles, params: ShapeParams | None = None
) -> StictionTestResult:
    """Singhal & Salsbury (2005) area ratio R = mean(A1/A2) on half-cycles of the error ``x``.

    The mean is geometric, so that the ratios of growing and decaying cycles of a randomly
    excited oscillation (R_i and 1/R_i) cancel instead of biasing R above 1.
    """
    p = params or ShapeParams()
    if hc.count < p.min_half_cycles:
        return StictionTestResult("area_ratio", None, "undecided", f"{hc.count} half-cycles")
    ax = np.abs(x - mean(x))
    csum = np.concatenate(([0.0], np.cumsum(ax)))
    a, b = hc.starts, hc.stops
    k = first_peaks(ax, a, b)
    # the peak sample is shared half and half, or short half-cycles are biased above 1
    a1 = csum[k] - csum[a] + 0.5 * ax[k]
    a2 = csum[b] - csum[k + 1] + 0.5 * ax[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.where(a2 > 0, a1 / a2, 10.0)
    # geometric mean: growing and decaying cycles (random excitation) cancel out
    r = float(np.exp(np.mean(np.log(np.clip(ratios, 0.1, 10.0)))))
    return StictionTestResult(
        "area_ratio", r, three_way(r, p.area_yes, p.area_no), f"{hc.count} half-cycles"
    )
