"""The loop performance indices (issue 49 item 1): travel and reversals exact on signals
computed by hand, per day right at any length and sample time; the Harris index against its
analytic value where the disturbance model and the delay are known."""

from __future__ import annotations

import numpy as np
import pytest

from plantcheck.diagnosis.kpis import harris_index, play, travel, window_kpis


def test_play_ignores_moves_within_its_band() -> None:
    x = np.array([50.0, 50.04, 49.97, 50.2, 50.1, 50.5, 49.0])
    assert play(x, 0.1).tolist() == pytest.approx([50.0, 50.0, 50.0, 50.15, 50.15, 50.45, 49.05])


def _play_by_sample(x: np.ndarray, width: float) -> list[float]:
    """The operator's definition, one sample at a time."""
    y, out = float(x[0]), []
    for v in x.tolist():
        if v > y + width / 2:
            y = v - width / 2
        elif v < y - width / 2:
            y = v + width / 2
        out.append(y)
    return out


@pytest.mark.parametrize("n", [1, 2, 3, 5, 64, 1000, 3601])
@pytest.mark.parametrize("width", [0.0, 0.1, 2.0])
def test_play_is_its_definition_to_the_bit(n: int, width: float) -> None:
    """The prefix scan gives what the sample-by-sample operator gives, exactly: on a random
    walk, on white noise about a level, and on a quantised signal that sits on its steps."""
    rng = np.random.default_rng(n)
    for x in (
        50.0 + np.cumsum(rng.normal(0.0, 0.2, n)),
        50.0 + rng.normal(0.0, 0.1, n),
        np.round(50.0 + np.cumsum(rng.normal(0.0, 0.05, n)), 1),
    ):
        assert play(x, width).tolist() == _play_by_sample(x, width)


@pytest.mark.parametrize("ts", [0.1, 1.0, 7.5])
@pytest.mark.parametrize("cycles", [1, 3, 10])
def test_travel_and_reversals_of_a_triangle_wave(ts: float, cycles: int) -> None:
    """OP 40 -> 60 -> 40, ``cycles`` times: 40 % of travel and two reversals per cycle but
    the last (the record ends at its minimum), with noise inside the play's band."""
    one = np.concatenate([np.linspace(40, 60, 21), np.linspace(60, 40, 21)[1:]])
    x = np.concatenate([one[:-1]] * cycles + [one[-1:]])
    x = x + np.random.default_rng(1).uniform(-0.03, 0.03, x.size)
    t = travel(x, ts, deadband=0.1)
    assert t is not None
    days = x.size * ts / 86_400.0
    # the play trails by half its band (0.05 %) at each turn: the first half-cycle travels
    # 19.95 %, every later one 19.9 %; the noise at the turns moves that by up to 0.03 %
    reversals = 2 * cycles - 1
    assert t.reversals_per_day * days == pytest.approx(reversals)
    assert t.travel_per_day * days == pytest.approx(39.8 * cycles + 0.05, abs=0.04 * 2 * cycles)


def test_a_still_signal_neither_travels_nor_reverses() -> None:
    x = 50 + np.random.default_rng(2).uniform(-0.04, 0.04, 5000)
    t = travel(x, 1.0, deadband=0.1)
    # at most one move, less than the band, off where the record started
    assert t is not None and t.reversals_per_day == 0
    assert t.travel_per_day * 5000 / 86_400 < 0.1


def _ar1(phi: float, n: int, seed: int) -> np.ndarray:
    a = np.random.default_rng(seed).normal(size=n)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = phi * y[k - 1] + a[k]
    return y


CASES = [(phi, b) for phi in (0.3, 0.6, 0.8, 0.9, 0.95) for b in (1, 2, 4, 8)]


@pytest.mark.parametrize(("phi", "b"), CASES)
def test_harris_index_of_an_ar1_disturbance(phi: float, b: int) -> None:
    """Uncontrolled AR(1) y = a/(1 − φq⁻¹) with a delay of b samples: the minimum variance
    is σ²_a(1 + φ² + ... + φ^{2(b−1)}), the variance σ²_a/(1 − φ²): η = 1 − φ^{2b}."""
    y = _ar1(phi, 20_000, seed=int(100 * phi) + b)
    assert harris_index(y, b, order=10) == pytest.approx(1 - phi ** (2 * b), abs=0.05)


def test_minimum_variance_control_reads_one() -> None:
    """Under minimum-variance control the error is an MA(b−1) of the noise: η = 1."""
    a = np.random.default_rng(3).normal(size=20_000)
    e = a + 0.8 * np.concatenate([[0.0], a[:-1]])  # b = 2: e = (1 + ψ1 q⁻¹) a
    assert harris_index(e, 2, order=20) == pytest.approx(1.0, abs=0.05)


def test_window_kpis_say_where_the_dead_time_came_from() -> None:
    n = 3600
    pv = 50 + _ar1(0.9, n, 4) * 0.1
    op = 40 + np.linspace(0, 1, n)
    k = window_kpis(pv, op, np.full(n, 50.0), 1.0, auto_share=0.5, op_limit=None,
                    op_limit_share=0.0, dead_time_s=None, dead_time_source="no dead time",
                    baseline_sd=None)  # fmt: skip
    assert k["harris_index"] is None and k["harris_note"] == "no dead time"
    assert k["service_factor"] == 0.5 and k["op_limit"] is None
    k = window_kpis(pv, op, np.full(n, 50.0), 1.0, auto_share=None, op_limit=100.0,
                    op_limit_share=0.25, dead_time_s=3.0, dead_time_source="configured",
                    baseline_sd=0.05)  # fmt: skip
    assert 0 < k["harris_index"] <= 1 and k["dead_time_source"] == "configured"
    assert k["op_limit"] == {"value": 100.0, "share": 0.25} and k["variability_ratio"] > 1
