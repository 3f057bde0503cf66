"""Signal helpers: FFT ACF/CCF against direct sums, zero crossings, half-cycles, noise."""

from __future__ import annotations

import numpy as np

from plantcheck.diagnosis.signal_tools import (
    distinct_count,
    fast_fft_length,
    fft_acf,
    fft_ccf,
    first_order_lag,
    first_order_lags,
    first_order_recursion,
    first_peaks,
    half_cycles,
    hann,
    hysteresis_sign,
    log_grid,
    mean,
    noise_sigma,
    percentile,
    round_significant,
    sorted_unique,
    std,
    unit_grid,
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


def test_hysteresis_sign_is_its_definition() -> None:
    """Sample by sample: the sign changes only outside the band, in-band samples keep the
    last sign, leading ones take the first decided; +1 throughout when none is decided."""
    rng = np.random.default_rng(3)
    for x, band in (
        (np.sin(np.arange(500) / 9.0) + rng.normal(0.0, 0.3, 500), 0.5),
        (rng.normal(0.0, 0.1, 50), 0.15),
        (np.full(20, 0.1), 0.5),
        (np.array([0.0, 0.0, -1.0, 0.2, 1.0, np.nan, -0.1]), 0.5),
    ):
        expected, last = [], 0
        for v in x.tolist():
            last = 1 if v > band else -1 if v < -band else last
            expected.append(last)
        first = next((v for v in expected if v != 0), 1)
        expected = [v if v != 0 else first for v in expected]
        got = hysteresis_sign(x, band)
        assert got.dtype == np.int8
        assert got.tolist() == expected


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


def test_half_cycle_peaks_when_short_half_cycles_are_dropped() -> None:
    """Dropping short half-cycles leaves gaps between kept ones: each peak is still the
    largest |x| between its own start and stop."""
    rng = np.random.default_rng(3)
    x = np.sin(np.arange(2000) / 15.0) + 0.6 * rng.normal(size=2000)
    hc = half_cycles(x, 1.0, band=0.0, min_samples=4)
    assert hc.count > 10 and np.any(hc.stops[:-1] != hc.starts[1:])
    expected = [np.abs(x[a:b]).max() for a, b in zip(hc.starts, hc.stops, strict=True)]
    assert np.array_equal(hc.peak, expected)


def test_first_peaks_takes_the_first_of_tied_maxima() -> None:
    x = np.array([0.0, 2.0, 1.0, 2.0, 0.0, 5.0, 5.0, 1.0, 3.0, 0.0, 0.0])
    starts, stops = np.array([0, 4, 8]), np.array([4, 7, 10])
    assert first_peaks(x, starts, stops).tolist() == [1, 5, 8]
    assert first_peaks(x, starts[:0], stops[:0]).size == 0


def test_noise_sigma_ignores_slow_oscillation() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(5000)
    x = 5 * np.sin(2 * np.pi * t / 300) + 0.3 * rng.normal(size=t.size)
    assert abs(noise_sigma(x) - 0.3) < 0.03


def test_first_order_recursions_match_lfilter() -> None:
    """The numpy recursion equals ``scipy.signal.lfilter`` to rounding, over the poles the
    chain uses (fast lags to the Hägglund load counter's slow decay) and long windows."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(4)
    for n in (1, 7, 3600, 86400):
        x = rng.normal(size=n).cumsum() + 100.0
        for a in (1e-9, 0.05, 0.37, 0.9, 0.999, 0.99999):
            expected = lfilter([1.0 - a], [1.0, -a], x - x[0]) + x[0]
            assert np.allclose(first_order_lag(x, a), expected, rtol=1e-10, atol=0.0)
            assert np.allclose(
                first_order_recursion(x, a), lfilter([1.0], [1.0, -a], x), rtol=1e-10
            )
    poles = [0.0, 0.37, 0.6, 0.97]
    x = rng.normal(size=500)
    rows = first_order_lags(x, poles)
    assert np.array_equal(rows[0], x)
    for row, a in zip(rows[1:], poles[1:], strict=True):
        assert np.allclose(row, first_order_lag(x, a), rtol=1e-12)


def test_fast_fft_length_is_the_next_5_smooth_number() -> None:
    from scipy.fft import next_fast_len

    assert all(fast_fft_length(n) == next_fast_len(n, real=True) for n in range(1, 5000))


def test_log_grid_is_geomspace() -> None:
    """The identification's and the margins' grids: np.geomspace's points, to rounding."""
    for start, stop, num in ((0.6, 1.6, 7), (1e-5, np.pi, 800), (13, 600, 19), (2.0, 2.0, 1)):
        assert np.allclose(log_grid(start, stop, num), np.geomspace(start, stop, num), rtol=1e-14)


def test_round_significant_is_the_formatted_value() -> None:
    """A plot's times and frequencies rounded in one pass are what formatting each one to 4
    significant digits gives, zero and negative values included."""
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.lognormal(0, 5, 5000) * rng.choice([-1, 1], 5000), [0.0, 12345.678]])
    assert round_significant(x, 4) == [float(f"{v:.4g}") for v in x]


def test_percentile_is_numpys_to_the_bit() -> None:
    """The bicoherence's conditioning level: ``numpy.percentile``'s value, the sign of a zero
    included, on sizes from 1, quantised values with ties, and any percentile."""
    rng = np.random.default_rng(7)
    for trial in range(3000):
        x = rng.standard_normal(int(rng.integers(1, 500))) * 10 ** rng.uniform(-12, 12)
        if trial % 3 == 0:
            x = np.round(x / np.max(np.abs(x)), 1)
        q = float(rng.choice([0.0, 5.0, 25.0, 50.0, 75.0, 99.0, 100.0, rng.uniform(0, 100)]))
        assert repr(percentile(x.copy(), q)) == repr(float(np.percentile(x, q))), (x.size, q)


def test_hann_is_numpys_taper_and_read_only() -> None:
    w = hann(64)
    assert np.array_equal(w, np.hanning(64)) and not w.flags.writeable


def test_sorted_unique_and_unit_grid_are_numpys() -> None:
    """The identification's dead-time grids and the half-cycles' time base."""
    rng = np.random.default_rng(5)
    for size in (0, 1, 2, 17, 40):
        x = np.sort(np.round(rng.uniform(0, 20, size)))
        assert np.array_equal(sorted_unique(x), np.unique(x))
    assert np.array_equal(unit_grid(32), np.linspace(0.0, 1.0, 32))
    assert not unit_grid(32).flags.writeable


def test_distinct_count_is_numpys_unique_size() -> None:
    """The window checks' count of PV levels, NaN (a gap too long to fill) counted once."""
    rng = np.random.default_rng(6)
    for size in (0, 1, 2, 17, 400):
        x = np.round(rng.uniform(-5, 5, size))
        for holes in (0, 1, 3):
            y = x.copy()
            y[rng.integers(0, max(size, 1), holes if size else 0)] = np.nan
            assert distinct_count(y) == np.unique(y).size, (size, holes)
    assert distinct_count(np.array([0.0, -0.0, np.inf, -np.inf, np.inf])) == 3


def test_mean_and_std_are_numpys_to_the_bit() -> None:
    """The chain's mean and σ are numpy's values exactly, on any length, scale and stride, and
    hand other arrays (integers, 2-D, empty) to numpy."""
    rng = np.random.default_rng(7)
    for k in range(400):
        n = int(rng.integers(1, 9000))
        x = rng.normal(size=n) * 10.0 ** rng.uniform(-8, 8) + rng.uniform(-1e4, 1e4)
        if k % 3 == 0:
            x = x[::3]
        assert mean(x) == float(np.mean(x))
        assert std(x) == float(np.std(x))
    ints = np.arange(10)
    assert mean(ints) == 4.5 and std(ints) == float(np.std(ints))
    assert mean([1.0, 2.0]) == 1.5 and std([1.0, 3.0]) == 1.0  # type: ignore[arg-type]
    grid = np.arange(6.0).reshape(2, 3)
    assert mean(grid) == 2.5 and std(grid) == float(np.std(grid))
