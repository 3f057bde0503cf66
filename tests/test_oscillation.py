"""Oscillation detection (Hägglund + Thornhill composite)."""

from __future__ import annotations

import numpy as np
import pytest

from plantcheck.diagnosis import detect_oscillation
from plantcheck.diagnosis.oscillation import hagglund_loads, thornhill_regularity


@pytest.mark.parametrize("period", [20.0, 60.0, 300.0])
def test_noisy_sine_is_oscillating_with_its_period(period: float) -> None:
    rng = np.random.default_rng(0)
    t = np.arange(20000) * 0.5
    x = np.sin(2 * np.pi * t / period) + 0.3 * rng.normal(size=t.size)
    res = detect_oscillation(x, 0.5)
    assert res.oscillating
    assert res.period_s == pytest.approx(period, rel=0.03)
    assert res.amplitude == pytest.approx(1.0, rel=0.25)


@pytest.mark.parametrize("kind", ["white", "random_walk", "ar1"])
def test_noise_is_not_oscillating(kind: str) -> None:
    rng = np.random.default_rng(3)
    w = rng.normal(size=10000)
    x = {"white": w, "random_walk": np.cumsum(w), "ar1": np.zeros(10000)}[kind]
    if kind == "ar1":
        for k in range(1, x.size):
            x[k] = 0.95 * x[k - 1] + w[k]
    assert not detect_oscillation(x, 1.0).oscillating


def test_thornhill_regularity_of_a_clean_sine_is_high() -> None:
    t = np.arange(5000)
    reg = thornhill_regularity(np.sin(2 * np.pi * t / 100), 1.0)
    assert reg is not None
    assert reg.regularity > 10
    assert reg.period_s == pytest.approx(100, rel=0.01)


def test_hagglund_counts_only_large_half_cycles() -> None:
    t = np.arange(4000)
    x = np.sin(2 * np.pi * t / 100)  # 80 half-cycles, IAE = A·Tp/π ≈ 31.8 each
    assert hagglund_loads(x, 1.0, iae_lim=20.0, tsup_s=5000).load_count >= 78
    assert hagglund_loads(x, 1.0, iae_lim=40.0, tsup_s=5000).load_count == 0
