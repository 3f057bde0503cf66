"""Thornhill's ACF regularity (``diagnosis/acf_regularity.py``, Thornhill et al. 2003): a clean
sine is very regular (r far above 1), white noise has no regular oscillation."""

from __future__ import annotations

import numpy as np

from plantcheck.diagnosis.acf_regularity import thornhill_regularity


def test_a_sine_is_regular_with_its_period() -> None:
    t = np.arange(2000, dtype=np.float64)
    res = thornhill_regularity(np.sin(2 * np.pi * t / 50.0), ts=2.0)
    assert res is not None
    assert abs(res.period_s - 100.0) < 1.0  # 50 samples at 2 s
    assert res.regularity > 10.0


def test_white_noise_is_not_a_regular_oscillation() -> None:
    x = np.random.default_rng(3).normal(size=2000)
    res = thornhill_regularity(x, ts=1.0)
    assert res is None or res.regularity < 1.0
