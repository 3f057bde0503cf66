"""Window checks before any diagnosis (methods.md §1 and §3.2 steps IM/AIM 1–3).

Decides whether a window can be judged at all and prepares the signals for the tests:
gaps and NaN, manual mode, frozen sensor, quantisation/compression, OP saturation and
set-point changes (GI/DI indices, PCU; definitions are our reconstruction [R]).

Units: OP in % (0–100); PV and SP in engineering units (ratios are unit-free).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import FloatArray, noise_sigma

BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class WindowParams:
    """Thresholds of the window checks; every one is a default to calibrate [R unless noted]."""

    min_samples: int = 100
    """Fewer usable samples than this -> ``insufficient_data``."""
    max_missing_fraction: float = 0.05
    """More missing (NaN) samples than this fraction -> ``data_quality`` (methods §1.1)."""
    max_fill_gap: int = 3
    """Gaps of at most this many samples are filled (forward fill, methods §1.1)."""
    min_auto_fraction: float = 0.9
    """Less automatic-mode time than this -> ``manual_mode`` (methods §1.2)."""
    quantised_unique_fraction: float = 0.2
    """PV with fewer distinct values than this fraction is quantised or compressed (§1.3, [V])."""
    quantised_min_levels: int = 8
    """PV with fewer distinct levels than this cannot be judged -> ``data_quality``."""
    frozen_fraction: float = 0.98
    """Share of unchanged consecutive PV samples above which the sensor is frozen."""
    saturation_band: float = 2.0
    """OP within this many % of 0 or 100 counts as saturated (``controllerPlotFcn3.m`` [V])."""
    saturation_pin: float = 0.1
    """A saturated OP sample lies within this many % (at most 5 % of the OP range) of the
    window's own extreme: a clamped output sits at its limit [R]."""
    saturation_fraction: float = 0.5
    """Saturated longer than this fraction of the window -> ``saturation`` ([V], not PCU)."""
    gi_limit: float = 0.1
    """Global SP index GI above this -> set point not stationary (PCU GI, [R])."""
    di_limit: float = 0.05
    """Point-wise SP index DI above this -> set-point step (PCU DI, [R])."""
    min_segment_fraction: float = 0.5
    """With SP steps, the longest constant-SP segment must cover this share of the window."""


@dataclass(frozen=True)
class WindowReport:
    """Outcome of the window checks.

    ``verdict`` is None when the window can be diagnosed, otherwise one of
    ``insufficient_data``, ``data_quality``, ``manual_mode``, ``saturation``.
    ``segment`` is the [start, stop) sample range to analyse; the cleaned, gap-filled signals
    cover the whole window.
    """

    verdict: str | None
    notes: list[str]
    pv: FloatArray
    op: FloatArray
    sp: FloatArray
    segment: tuple[int, int]
    indices: dict[str, float] = field(default_factory=dict)
    quantised: bool = False
    sp_limited: bool = False
    """``insufficient_data`` only because set-point steps leave no long constant-SP stretch:
    tests that read the whole window (stick-slip events) still apply."""


def fill_short_gaps(x: FloatArray, max_gap: int) -> tuple[FloatArray, int]:
    """Fill NaN runs: runs of <= ``max_gap`` forward-filled, longer ones linearly interpolated.

    Returns the filled array and the length of the longest gap.
    """
    bad = ~np.isfinite(x)
    if not bad.any():
        return x, 0
    good_idx = np.flatnonzero(~bad)
    if good_idx.size == 0:
        return x, int(x.size)
    # run lengths of NaN
    edges = np.diff(np.concatenate(([0], bad.astype(np.int8), [0])))
    run_start = np.flatnonzero(edges == 1)
    run_stop = np.flatnonzero(edges == -1)
    longest = int((run_stop - run_start).max())
    idx = np.arange(x.size)
    filled = np.interp(idx, good_idx, x[good_idx])
    # forward-fill short runs (methods §1.1); long runs keep the interpolation
    prev = np.maximum.accumulate(np.where(bad, 0, idx))
    short = np.zeros(x.size, dtype=bool)
    for a, b in zip(run_start, run_stop, strict=True):
        if b - a <= max_gap and a > 0:
            short[a:b] = True
    filled[short] = x[prev[short]]
    return np.asarray(filled, dtype=np.float64), longest


def _longest_constant_segment(sp: FloatArray, step_tol: float) -> tuple[int, int]:
    """Longest [start, stop) run of ``sp`` without a step larger than ``step_tol``."""
    steps = np.flatnonzero(np.abs(np.diff(sp)) > step_tol) + 1
    bounds = np.concatenate(([0], steps, [sp.size]))
    lengths = np.diff(bounds)
    i = int(np.argmax(lengths))
    return int(bounds[i]), int(bounds[i + 1])


def check_window(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray | None = None,
    auto: BoolArray | None = None,
    params: WindowParams | None = None,
) -> WindowReport:
    """Run the §1 window checks on one loop window.

    Parameters
    ----------
    pv, op:
        Process variable (engineering units) and controller output (% 0–100), NaN = gap.
    sp:
        Set point (same units as PV); None means constant set point (estimated as mean PV).
    auto:
        True where the controller is in automatic (AUTO/CAS); None means always automatic.
    """
    p = params or WindowParams()
    notes: list[str] = []
    n = int(pv.size)
    indices: dict[str, float] = {}
    sp_arr = np.full(n, np.nan) if sp is None else np.asarray(sp, dtype=np.float64)
    empty = WindowReport("insufficient_data", notes, pv, op, sp_arr, (0, n), indices)
    if n < p.min_samples:
        notes.append(f"only {n} samples; at least {p.min_samples} are needed for a diagnosis")
        return empty

    # manual mode: samples outside AUTO/CAS are left out (contracts §1)
    if auto is not None:
        auto_frac = float(np.mean(auto))
        indices["auto_fraction"] = auto_frac
        if auto_frac < p.min_auto_fraction:
            notes.append(
                f"loop in automatic only {100 * auto_frac:.0f} % of the window "
                f"(needs {100 * p.min_auto_fraction:.0f} %)"
            )
            return WindowReport("manual_mode", notes, pv, op, sp_arr, (0, n), indices)
        if auto_frac < 1.0:
            pv = np.where(auto, pv, np.nan)
            op = np.where(auto, op, np.nan)
            notes.append(f"{int(np.sum(~auto))} manual-mode samples left out")

    missing = ~np.isfinite(pv) | ~np.isfinite(op)
    miss_frac = float(np.mean(missing))
    indices["missing_fraction"] = miss_frac
    if miss_frac >= 1.0:
        notes.append("PV or OP has no numeric value in the whole window")
        return WindowReport("data_quality", notes, pv, op, sp_arr, (0, n), indices)
    if n - int(missing.sum()) < p.min_samples:
        notes.append(
            f"only {n - int(missing.sum())} samples with both PV and OP; "
            f"at least {p.min_samples} are needed"
        )
        return WindowReport("insufficient_data", notes, pv, op, sp_arr, (0, n), indices)
    if miss_frac > p.max_missing_fraction:
        notes.append(
            f"{100 * miss_frac:.1f} % of samples missing "
            f"(limit {100 * p.max_missing_fraction:.0f} %)"
        )
        return WindowReport("data_quality", notes, pv, op, sp_arr, (0, n), indices)
    pv_f, gap_pv = fill_short_gaps(np.asarray(pv, dtype=np.float64), p.max_fill_gap)
    op_f, gap_op = fill_short_gaps(np.asarray(op, dtype=np.float64), p.max_fill_gap)
    if miss_frac > 0:
        notes.append(
            f"{int(missing.sum())} missing samples filled (longest gap {max(gap_pv, gap_op)})"
        )
    if sp is None or not np.isfinite(sp_arr).any():
        if sp is None:
            notes.append("no SP column: set point assumed constant (mean of PV)")
        sp_f = np.full(n, float(np.mean(pv_f)))
    else:
        sp_f, _ = fill_short_gaps(sp_arr, p.max_fill_gap)

    # frozen sensor and quantisation (methods §1.3)
    pv_range = float(np.ptp(pv_f))
    if pv_range == 0.0:
        notes.append("PV is constant over the window (frozen sensor or no measurement)")
        return WindowReport("data_quality", notes, pv_f, op_f, sp_f, (0, n), indices)
    unchanged = float(np.mean(np.diff(pv_f) == 0.0))
    indices["pv_unchanged_fraction"] = unchanged
    if unchanged > p.frozen_fraction:
        notes.append(
            f"PV unchanged on {100 * unchanged:.0f} % of samples (frozen sensor or heavy "
            "historian compression)"
        )
        return WindowReport("data_quality", notes, pv_f, op_f, sp_f, (0, n), indices)
    n_levels = int(np.unique(pv_f).size)
    unique_frac = n_levels / n
    indices["pv_unique_fraction"] = unique_frac
    if n_levels < p.quantised_min_levels:
        notes.append(f"PV takes only {n_levels} distinct values: too coarsely quantised to judge")
        return WindowReport("data_quality", notes, pv_f, op_f, sp_f, (0, n), indices)
    quantised = unique_frac < p.quantised_unique_fraction
    if quantised:
        notes.append(
            f"PV quantised or compressed ({100 * unique_frac:.1f} % distinct values): "
            "shape-based stiction tests are less reliable"
        )

    # OP saturation (methods §1.4)
    op_pp = float(np.ptp(op_f))
    band = p.saturation_band
    if op_pp == 0.0:
        if op_f[0] <= band or op_f[0] >= 100.0 - band:
            # clamped at a limit the whole window: saturation by definition (methods §1.4)
            indices["saturation_fraction"] = 1.0
            notes.append(f"OP held at {op_f[0]:g} % (a limit) over the whole window")
            return WindowReport("saturation", notes, pv_f, op_f, sp_f, (0, n), indices, quantised)
        notes.append("OP constant over the window: controller in manual or output frozen")
        return WindowReport("manual_mode", notes, pv_f, op_f, sp_f, (0, n), indices)
    # A saturated controller output is clamped: it sits at its extreme value, near 0 or 100 %.
    op_lo, op_hi = float(np.min(op_f)), float(np.max(op_f))
    pin = min(p.saturation_pin, 0.05 * op_pp)
    pinned_lo = (op_f <= band) & (op_f <= op_lo + pin)
    pinned_hi = (op_f >= 100.0 - band) & (op_f >= op_hi - pin)
    sat_frac = float(np.mean(pinned_lo | pinned_hi))
    indices["saturation_fraction"] = sat_frac
    if sat_frac > p.saturation_fraction:
        notes.append(f"OP within {p.saturation_band:g} % of a limit {100 * sat_frac:.0f} % of time")
        return WindowReport("saturation", notes, pv_f, op_f, sp_f, (0, n), indices, quantised)

    # set-point stationarity: GI (global) and DI (point-wise), PCU [R]
    eps = 1e-12
    gi = float(np.ptp(sp_f)) / (pv_range + eps)
    di = float(np.max(np.abs(np.diff(sp_f)))) / (pv_range + eps)
    indices["sp_gi"] = gi
    indices["sp_di"] = di
    segment = (0, n)
    if gi >= p.gi_limit and di >= p.di_limit:
        step_tol = max(p.di_limit * pv_range, 3.0 * noise_sigma(sp_f))
        segment = _longest_constant_segment(sp_f, step_tol)
        seg_len = segment[1] - segment[0]
        if seg_len < max(p.min_samples, p.min_segment_fraction * n):
            notes.append(
                "set point changes too often: no constant-SP stretch long enough "
                f"(longest {seg_len} samples)"
            )
            return WindowReport(
                "insufficient_data", notes, pv_f, op_f, sp_f, segment, indices, quantised, True
            )
        notes.append(
            f"set-point steps in the window: analysed the constant-SP stretch "
            f"{segment[0]}–{segment[1]} ({seg_len} samples)"
        )
    elif gi >= p.gi_limit:
        notes.append("set point moves slowly (cascade or ramp): analysed the control error")
    return WindowReport(None, notes, pv_f, op_f, sp_f, segment, indices, quantised)
