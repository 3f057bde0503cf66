"""Window checks (methods.md §1): each reason a window cannot be judged."""

from __future__ import annotations

import numpy as np

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.window import check_window

RNG = np.random.default_rng(0)
N = 2000
PV = 50 + np.cumsum(RNG.normal(0, 0.05, N)) + RNG.normal(0, 0.2, N)
OP = 40 + np.cumsum(RNG.normal(0, 0.05, N))


def test_clean_window_passes() -> None:
    rep = check_window(PV, OP)
    assert rep.verdict is None
    assert any("no SP column" in n for n in rep.notes)


def test_short_gaps_filled_long_missing_is_data_quality() -> None:
    pv = PV.copy()
    pv[100:103] = np.nan
    rep = check_window(pv, OP)
    assert rep.verdict is None and np.isfinite(rep.pv).all()
    pv[200:400] = np.nan
    assert check_window(pv, OP).verdict == "data_quality"


def test_manual_mode_from_mode_signal_and_from_frozen_op() -> None:
    auto = np.ones(N, dtype=bool)
    auto[: N // 2] = False
    assert check_window(PV, OP, auto=auto).verdict == "manual_mode"
    assert check_window(PV, np.full(N, 37.0)).verdict == "manual_mode"


def test_saturation_needs_a_clamped_output() -> None:
    op = np.where(np.arange(N) < 1500, 100.0, OP)
    assert check_window(PV, op).verdict == "saturation"
    # an OP that only wanders near 0 (scaled data) is not clamped
    assert check_window(PV, 0.01 * (OP - 40)).verdict is None


def test_frozen_and_quantised_pv() -> None:
    assert check_window(np.full(N, 3.0), OP).verdict == "data_quality"
    coarse = np.round(PV / 5) * 5  # only a few levels
    assert check_window(coarse, OP).verdict == "data_quality"


def test_sp_steps_keep_longest_constant_stretch() -> None:
    sp = np.where(np.arange(N) < 300, 50.0, 55.0)
    rep = check_window(PV, OP, sp)
    assert rep.verdict is None
    assert rep.segment == (300, N)


def test_diagnose_rejects_unknown_loop_type() -> None:
    try:
        diagnose(PV, OP, 1.0, loop_type="valve")
    except ValueError as exc:
        assert "loop_type" in str(exc)
    else:  # pragma: no cover
        raise AssertionError("no error")
