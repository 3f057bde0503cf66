"""Regularity of an oscillation from the zero crossings of its autocorrelation function
(Thornhill, Huang & Zhang 2003, J. Process Control 13:91; methods.md §2.4)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from plantcheck.diagnosis.signal_tools import (
    FloatArray,
    detrend,
    fft_acf,
    interpolated_zero_crossings,
)


@dataclass(frozen=True)
class RegularityResult:
    """Thornhill ACF regularity: ``r`` (dimensionless), mean period and its std (s)."""

    regularity: float
    period_s: float
    period_std_s: float
    n_intervals: int


def thornhill_regularity(
    x: FloatArray, ts: float, n_half: int = 10, min_half: int = 4, max_lag_fraction: float = 0.75
) -> RegularityResult | None:
    """Regularity of an oscillation from the zero crossings of its ACF (Thornhill et al. 2003).

    r = (1/3)·mean(Tp)/std(Tp) over ACF half-periods 2…(n_half+1); None when fewer than
    ``min_half`` intervals exist (no oscillation can be asserted). The ACF is read up to
    ``max_lag_fraction`` of the record, so that short records of slow oscillations still show
    enough half-periods.
    """
    acf = fft_acf(detrend(x), max(8, int(max_lag_fraction * x.size)))
    zc = interpolated_zero_crossings(acf)
    halves = np.diff(zc)[:n_half]
    if halves.size < min_half:
        return None
    tp = 2.0 * halves * ts
    std = float(np.std(tp, ddof=1))
    mean = float(np.mean(tp))
    r = mean / (3.0 * std) if std > 0 else math.inf
    return RegularityResult(min(r, 1e3), mean, std, int(halves.size))
