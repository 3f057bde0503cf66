"""Oscillation detection (Hägglund + Thornhill composite)."""

from __future__ import annotations

import numpy as np
import pytest

from plantcheck.diagnosis import detect_oscillation
from plantcheck.diagnosis.oscillation import (
    faster_oscillation,
    hagglund_loads,
    thornhill_regularity,
)


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


def test_faster_oscillation_beneath_a_slow_one_is_found() -> None:
    """A 14 s square-wave cycle under a stronger 130 s sinusoid: the composite test reports the
    sinusoid, the separation (Thornhill et al. 2003) the cycle."""
    rng = np.random.default_rng(4)
    t = np.arange(3600) * 0.5
    cycle = 0.6 * np.sign(np.sin(2 * np.pi * t / 14.0))
    x = 2.0 * np.sin(2 * np.pi * t / 130.0) + cycle + 0.1 * rng.normal(size=t.size)
    dominant = detect_oscillation(x, 0.5)
    assert dominant.oscillating and dominant.period_s == pytest.approx(130, rel=0.05)
    fast = faster_oscillation(x, 0.5, dominant.period_s)
    assert fast is not None and fast.period_s == pytest.approx(14, rel=0.03)
    # without the cycle nothing is found beneath the sinusoid
    assert faster_oscillation(x - cycle, 0.5, dominant.period_s) is None


@pytest.mark.parametrize("shape", ["square", "sawtooth"])
def test_harmonics_of_a_stick_slip_cycle_are_not_a_faster_oscillation(shape: str) -> None:
    """The odd harmonics of a square wave (and every harmonic of a saw-tooth) survive the
    separation's high-pass; they are no oscillation of their own."""
    rng = np.random.default_rng(5)
    t = np.arange(3600) * 0.5
    phase = (t / 40.0) % 1.0
    x = np.sign(phase - 0.5) if shape == "square" else 2.0 * phase - 1.0
    x = x + 0.05 * rng.normal(size=t.size)
    dominant = detect_oscillation(x, 0.5)
    assert dominant.oscillating and dominant.period_s == pytest.approx(40, rel=0.03)
    assert faster_oscillation(x, 0.5, dominant.period_s) is None
