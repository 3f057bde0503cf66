"""Two model files read on the same windows (``cause_model_fit.paired_macro_f1_difference``):
the macro-F1 difference, and a paired bootstrap standard error that is zero for two files that
agree and grows with the windows they read differently."""

from __future__ import annotations

import numpy as np

from plantcheck.service.cause_model_fit import macro_f1, paired_macro_f1_difference


def _labels(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 6, n)


def test_files_that_agree_differ_by_nothing() -> None:
    y = _labels(2_000, 1)
    pred = np.where(np.arange(y.size) % 10 == 0, (y + 1) % 6, y)
    diff, se = paired_macro_f1_difference(y, pred, pred.copy(), 6)
    assert diff == 0.0 and se == 0.0


def test_the_difference_and_its_spread_follow_the_windows_read_differently() -> None:
    y = _labels(4_000, 2)
    base = np.where(np.arange(y.size) % 10 == 0, (y + 1) % 6, y)
    better = base.copy()
    better[: y.size // 2] = y[: y.size // 2]  # half the base's errors mended
    diff, se = paired_macro_f1_difference(y, better, base, 6)
    assert diff == macro_f1(y, better, 6)[0] - macro_f1(y, base, 6)[0]
    assert diff > 0.04 and 0.0 < se < diff / 5
    # one window apart (the first, one of the base's errors, mended): the difference is within
    # three standard errors of nothing
    near = base.copy()
    near[:6] = y[:6]
    d2, se2 = paired_macro_f1_difference(y, near, base, 6)
    assert 0.0 < d2 < 3 * se2 + 1e-12


def test_too_few_resamples_give_no_spread() -> None:
    y = _labels(100, 3)
    diff, se = paired_macro_f1_difference(y, y, y, 6, resamples=1)
    assert diff == 0.0 and np.isnan(se)
