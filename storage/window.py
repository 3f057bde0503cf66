"""Align a loop's stored samples on one time base (pure numpy; no database here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
SIGNALS = ("sp", "pv", "op", "mv", "mode")


@dataclass(frozen=True)
class LoopWindow:
    """SP/PV/OP/MV/mode on one grid of ``sample_time_s`` seconds starting at ``start_us``.

    Missing or Bad samples are NaN. ``coverage`` is the fraction of grid points where both PV
    and OP are good; ``signals`` lists which signals have any stored sample.
    """

    start_us: int
    sample_time_s: float
    t_us: NDArray[np.int64]
    values: dict[str, FloatArray]
    coverage: float
    signals: tuple[str, ...]

    def __getitem__(self, name: str) -> FloatArray:
        return self.values[name]


def median_spacing_s(ts_us: NDArray[np.int64]) -> float | None:
    """Median spacing (s) of sorted unique timestamps; None with fewer than 2."""
    u = np.unique(ts_us)
    if u.size < 2:
        return None
    return float(np.median(np.diff(u))) / 1e6


def align(
    series: dict[str, tuple[NDArray[np.int64], FloatArray]],
    start_us: int,
    end_us: int,
    sample_time_s: float | None = None,
) -> LoopWindow:
    """Put each signal's (timestamps µs, values) on a common grid over [start, end).

    The grid step is ``sample_time_s`` or the median spacing of PV's timestamps. Each sample
    goes to its nearest grid point (the later sample wins a tie); grid points without a sample
    stay NaN, so gaps remain gaps.
    """
    ts = sample_time_s
    if ts is None:
        pv_t = series.get("pv", (np.empty(0, np.int64), np.empty(0)))[0]
        ts = median_spacing_s(pv_t) or 1.0
    step_us = max(1, round(ts * 1e6))
    n = max(0, (end_us - start_us + step_us - 1) // step_us)
    grid = start_us + step_us * np.arange(n, dtype=np.int64)
    values: dict[str, FloatArray] = {}
    present = []
    for sig in SIGNALS:
        out = np.full(n, np.nan)
        if sig in series and series[sig][0].size:
            t, v = series[sig]
            present.append(sig)
            idx = np.rint((t - start_us) / step_us).astype(np.int64)
            ok = (idx >= 0) & (idx < n)
            out[idx[ok]] = v[ok]
        values[sig] = out
    good = np.isfinite(values["pv"]) & np.isfinite(values["op"])
    coverage = float(good.mean()) if n else 0.0
    return LoopWindow(start_us, ts, grid, values, coverage, tuple(present))
