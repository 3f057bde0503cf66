"""diagnosis/tuning.py: the idle index's filter follows the loop's own time scale."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import plant_window

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.tuning import (
    TuningParams,
    correlation_time,
    identify_pi,
    idle_filter_s,
)
from plantcheck.simulator.cases import generate_short_window_cases
from plantcheck.simulator.loop import simulate_loop


def _ar1(phi: float, n: int = 20_000, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = np.zeros(n)
    e = rng.normal(size=n)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + e[k]
    return x


@pytest.mark.parametrize("phi", [0.5, 0.9, 0.99])
def test_correlation_time_of_ar1_is_its_decay(phi: float) -> None:
    """ACF of AR(1) is phi^k: it falls to 1/e at k = -1 / ln phi samples."""
    expected = -1.0 / np.log(phi)
    got = correlation_time(_ar1(phi), ts=2.0) / 2.0
    assert got == pytest.approx(expected, rel=0.3, abs=1.0)


def test_filter_is_half_ti_or_half_the_error_correlation_time() -> None:
    p = TuningParams()
    white = np.random.default_rng(3).normal(size=5000)
    assert idle_filter_s(white, 1.0, 40.0, p) == pytest.approx(20.0)  # noise: Ti decides
    slow = _ar1(0.995)
    assert idle_filter_s(slow, 1.0, 40.0, p) > 50.0  # a slow recovery: its own time scale
    assert idle_filter_s(np.zeros(100), 0.5, None, p) == pytest.approx(5.0)  # 10 samples


def test_a_low_gain_loop_without_set_point_steps_is_sluggish() -> None:
    """Kc 0.2 on a fast flow loop: load recoveries last about 100 Ti. Filtered over 0.5 Ti the
    increments read the noise the proportional action copies into OP (index -0.17, `ok`)."""
    name = "sluggish_tuning-flow-n6000-steps0-limit70-continuous-noise0.5-r0"
    case = plant_window(name)
    r = simulate_loop(case.config)
    d = diagnose(r.pv, r.op, case.config.sample_time_s, sp=r.sp, loop_type="flow", quantify=False)
    assert d.cause == "sluggish_tuning", d.notes
    assert d.indices["idle_index"] is not None and d.indices["idle_index"] > 0


def test_the_controller_direction_survives_a_compressed_pv() -> None:
    """Every generated process raises its PV with OP; a historian's compression (the PV held
    until it has moved by its dead band) made the sample-by-sample regression read the
    opposite in 9 of the 48 compressed windows of this seed. Block means read it right."""
    cases = [c for c in generate_short_window_cases(seed=1, per_cell=4) if "compressed" in c.name]
    assert len(cases) == 48
    for c in cases:
        r = simulate_loop(c.config)
        assert identify_pi(r.op, r.pv, r.sp, c.config.sample_time_s).gain_sign == 1, c.name
