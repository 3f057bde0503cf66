"""Stiction trend per valve and the date its S is projected to pass a limit (methods.md §6.1
rule 6, maintenance scheduling: Bacci di Capaci & Scali 2014).

From a history of (time, S, J, reliable) estimates of one valve: only reliable estimates are
used; the trend is the Theil–Sen slope (robust to the odd wrong window) in % of travel per week;
the current level is the median of the most recent estimates; the projected crossing of the
per-valve limit (default 2 % of travel) follows the robust line. Times are POSIX seconds (UTC).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

WEEK_S = 7 * 24 * 3600.0


@dataclass(frozen=True)
class TrendParams:
    """Trend settings."""

    limit: float = 2.0
    """S (% of travel) above which the valve needs maintenance (per-valve setting)."""
    min_estimates: int = 3
    """Fewest reliable estimates for a trend (methods §6.1 rule 6)."""
    recent: int = 5
    """The current level is the median of this many latest reliable estimates."""
    max_horizon_weeks: float = 520.0
    """Projections further out than this (10 years) are reported as None."""


@dataclass(frozen=True)
class StictionTrend:
    """Trend of one valve's S: slope (%/week), current S and J (%), projected crossing time."""

    n_used: int
    slope_per_week: float | None
    current_S: float | None
    current_J: float | None
    limit: float
    above_limit: bool
    projected_crossing_s: float | None
    note: str


def theil_sen_slope(x: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    """The median of the slopes between every two points of distinct x (Theil 1950, Sen 1968):
    ``scipy.stats.theilslopes(y, x).slope`` to the bit, computed as it does, without importing
    ``scipy.stats`` (1.5 s, which every service process paid through the store's reports)."""
    dx = x[:, np.newaxis] - x
    dy = y[:, np.newaxis] - y
    right = dx > 0
    return float(np.median(dy[right] / dx[right]))


def stiction_trend(
    times_s: ArrayLike,
    S: ArrayLike,
    J: ArrayLike,
    reliable: ArrayLike,
    params: TrendParams | None = None,
) -> StictionTrend:
    """Robust trend of S for one valve and when it passes ``params.limit``."""
    p = params or TrendParams()
    t = np.asarray(times_s, dtype=np.float64)
    s = np.asarray(S, dtype=np.float64)
    j = np.asarray(J, dtype=np.float64)
    ok = np.asarray(reliable, dtype=bool) & np.isfinite(s) & np.isfinite(t)
    t, s, j = t[ok], s[ok], j[ok]
    order = np.argsort(t)
    t, s, j = t[order], s[order], j[order]
    n = int(t.size)
    if n == 0:
        return StictionTrend(0, None, None, None, p.limit, False, None, "no reliable estimate")
    cur_s = float(np.median(s[-p.recent :]))
    jr = j[-p.recent :]
    cur_j = float(np.median(jr[np.isfinite(jr)])) if np.isfinite(jr).any() else None
    above = cur_s >= p.limit
    if n < p.min_estimates or np.ptp(t) <= 0:
        note = f"{n} reliable estimates: at least {p.min_estimates} are needed for a trend"
        return StictionTrend(n, None, cur_s, cur_j, p.limit, above, None, note)
    slope = theil_sen_slope(t, s)
    # intercept as the median residual: scipy's median(S) − slope·median(t) is pulled by outliers
    intercept = float(np.median(s - slope * t))
    per_week = slope * WEEK_S
    crossing: float | None = None
    if above:
        note = f"S = {cur_s:.2f} % is at or above the limit {p.limit:g} %: maintenance due"
    elif slope <= 0:
        note = "S is not increasing: no crossing of the limit projected"
    else:
        t_cross = (p.limit - intercept) / slope
        t_cross = max(t_cross, float(t[-1]))
        if (t_cross - t[-1]) / WEEK_S > p.max_horizon_weeks:
            note = "S grows too slowly to pass the limit within 10 years"
        else:
            crossing = t_cross
            weeks = (t_cross - t[-1]) / WEEK_S
            note = f"S projected to pass {p.limit:g} % in {weeks:.1f} weeks"
    return StictionTrend(n, per_week, cur_s, cur_j, p.limit, above, crossing, note)
