"""Peak finding in numpy (``diagnosis/peaks.py``) returns exactly what
``scipy.signal.find_peaks`` returns: random walks, white noise, quantised signals with plateaus,
every prominence, height and distance the chain uses, and the edge cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import find_peaks, peak_prominences

from plantcheck.diagnosis.peaks import (
    highest_peaks_apart,
    local_maxima,
    peaks_apart,
    prominences,
    prominent_extremes,
)


def _signals(seed: int, count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        n = int(rng.integers(3, 2500))
        kind = i % 4
        if kind == 0:
            x = rng.normal(size=n).cumsum()
        elif kind == 1:
            x = rng.normal(size=n)
        elif kind == 2:  # quantised: plateaus everywhere
            x = np.round(rng.normal(size=n) * 2) / 2
        else:  # a slow cycle under coarse quantisation
            x = np.round(np.sin(np.arange(n) / 30) * 5 + rng.normal(size=n) * 0.3)
        out.append(x)
    return out


@pytest.mark.parametrize("prominence", [0.0, 0.1, 0.5, 1.0, 3.0])
def test_prominent_extremes_equal_scipy(prominence: float) -> None:
    for x in _signals(1, 300):
        hi, lo = prominent_extremes(x, prominence)
        assert np.array_equal(hi, find_peaks(x, prominence=prominence)[0])
        assert np.array_equal(lo, find_peaks(-x, prominence=prominence)[0])


def test_prominences_equal_scipy() -> None:
    for x in _signals(2, 100):
        peaks = local_maxima(x)
        assert np.array_equal(peaks, find_peaks(x)[0])
        assert np.array_equal(prominences(x, peaks), peak_prominences(x, peaks)[0])


@pytest.mark.parametrize("height", [-1.0, 0.0, 0.5, 2.0])
def test_peaks_apart_equal_scipy(height: float) -> None:
    rng = np.random.default_rng(3)
    for x in _signals(3, 200):
        distance = int(rng.integers(1, 50))
        expected = find_peaks(x, height=height, distance=distance)[0]
        assert np.array_equal(peaks_apart(x, height, distance), expected)


@pytest.mark.parametrize("count", [1, 3, 12, 1000])
def test_highest_peaks_apart_are_the_highest_of_scipys(count: int) -> None:
    """The ``count`` highest of SciPy's peaks, highest first and equal heights in time order
    (quantised signals have many), however early the distance rule stops."""
    rng = np.random.default_rng(4)
    for x in _signals(4, 200):
        distance = int(rng.integers(1, 50))
        expected = find_peaks(x, height=0.0, distance=distance)[0]
        expected = expected[np.argsort(-x[expected], kind="stable")][:count]
        assert np.array_equal(highest_peaks_apart(x, 0.0, distance, count), expected)
    assert highest_peaks_apart(_signals(4, 1)[0], 0.0, 5, 0).size == 0


def test_short_and_flat_signals_have_no_peaks() -> None:
    for x in (np.zeros(0), np.ones(2), np.ones(50), np.arange(10.0)):
        assert local_maxima(x).size == 0
        assert all(p.size == 0 for p in prominent_extremes(x, 0.0))
    # a flat top counts once, at its middle (rounded down)
    assert local_maxima(np.array([0.0, 1.0, 1.0, 1.0, 1.0, 0.0])).tolist() == [2]
