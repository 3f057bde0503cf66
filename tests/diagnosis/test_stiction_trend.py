"""The trend's Theil–Sen slope, computed without ``scipy.stats``, is scipy's to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import theilslopes

from plantcheck.diagnosis.stiction_trend import theil_sen_slope


@pytest.mark.parametrize("n", [2, 3, 10, 57, 400])
def test_theil_sen_slope_is_scipys(n: int) -> None:
    rng = np.random.default_rng(n)
    # repeated times (two estimates in one diagnosis period) and outliers included
    t = np.round(rng.uniform(0.0, 30.0, n)) * 86_400.0
    s = 1.0 + 0.02 * t / 86_400.0 + rng.standard_t(2, n) * 0.1
    if np.ptp(t) == 0:
        t[-1] += 60.0
    assert theil_sen_slope(t, s) == theilslopes(s, t).slope
