"""Signal helpers: FFT ACF/CCF against direct sums, zero crossings, half-cycles, noise."""

from __future__ import annotations

import numpy as np

from plantcheck.diagnosis.signal_tools import (
    fft_acf,
    fft_ccf,
    half_cycles,
    noise_sigma,
    zero_crossings,
)


def test_fft_acf_matches_direct_sum() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=500)
    xc = x - x.mean()
    direct = np.array([xc[: x.size - k] @ xc[k:] for k in range(50)]) / (xc @ xc)
    assert np.allclose(fft_acf(x, 50), direct)


def test_fft_ccf_odd_for_quarter_period_shift() -> None:
    t = np.arange(2000)
    u = np.sin(2 * np.pi * t / 100)
    y = np.cos(2 * np.pi * t / 100)
    lags, c = fft_ccf(u, y, 60)
    assert abs(c[lags == 0][0]) < 0.05
    assert c[lags == -25][0] > 0.9 or c[lags == 25][0] > 0.9


def test_zero_crossings_with_hysteresis_ignore_noise() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(4000)
    x = np.sin(2 * np.pi * t / 200) + 0.05 * rng.normal(size=t.size)
    raw = zero_crossings(x, 0.0)
    hyst = zero_crossings(x, 0.2)
    assert raw.size > hyst.size
    assert abs(hyst.size - 40) <= 1


def test_half_cycles_shapes_are_rms_normalised() -> None:
    t = np.arange(1000)
    x = 3.0 * np.sin(2 * np.pi * t / 100 + 0.3)
    hc = half_cycles(x, 1.0)
    assert hc.count >= 17
    assert np.allclose(np.sqrt(np.mean(hc.shapes**2, axis=1)), 1.0)
    assert np.all(hc.shapes[:, 16] > 0)  # flipped positive
    assert np.allclose(hc.peak, 3.0, atol=0.01)


def test_noise_sigma_ignores_slow_oscillation() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(5000)
    x = 5 * np.sin(2 * np.pi * t / 300) + 0.3 * rng.normal(size=t.size)
    assert abs(noise_sigma(x) - 0.3) < 0.03
