"""diagnosis/spectral_peaks.py: each spectral peak band-passed and tested on its own, harmonics
not counted twice, and the few-cycle test's false-alarm rate on noise."""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from plantcheck.diagnosis.signal_tools import detrend
from plantcheck.diagnosis.spectral_peaks import few_cycle_peak, spectral_peaks


def test_harmonics_of_a_square_wave_are_one_oscillation() -> None:
    """A stick-slip square wave has strong odd harmonics; they are not oscillations of their
    own."""
    t = np.arange(8000, dtype=np.float64)
    x = np.sign(np.sin(2 * np.pi * t / 120.0)) + 0.05 * np.random.default_rng(1).normal(size=8000)
    peaks = spectral_peaks(detrend(x), 1.0)
    assert [round(p.period_s / 10) for p in peaks] == [12], [p.period_s for p in peaks]


def test_an_irregular_oscillation_is_found_in_its_band() -> None:
    """A period that wanders by ±15 % under heavy noise: regular once band-passed."""
    rng = np.random.default_rng(2)
    t = np.arange(5000, dtype=np.float64)
    phase = 2 * np.pi * np.cumsum((1 / 80.0) * (1 + 0.15 * np.sin(2 * np.pi * t / 1900.0)))
    x = np.sin(phase) + 0.8 * rng.normal(size=t.size)
    peaks = spectral_peaks(detrend(x), 1.0)
    assert peaks and peaks[0].oscillating, peaks
    assert 70 < peaks[0].period_s < 92
    assert peaks[0].regularity is not None and peaks[0].regularity > 1.0


def test_noise_has_no_peak_that_passes() -> None:
    rng = np.random.default_rng(3)
    found = 0
    for _ in range(100):
        x = lfilter([1.0], [1.0, -0.95], rng.normal(size=3000))
        found += any(p.oscillating for p in spectral_peaks(detrend(x), 1.0))
    assert found <= 2


def test_few_cycle_test_false_alarm_rate_on_coloured_noise_and_walks() -> None:
    """The rate quoted in ``few_cycle_peak``: at most 0.1 % per kind (here ≤ 1 of 600)."""
    rng = np.random.default_rng(4)
    hits = 0
    for k in range(600):
        e = rng.normal(size=int(rng.choice([300, 850, 1500])))
        x = np.cumsum(e) if k % 2 else lfilter([1.0], [1.0, -0.99], e)
        p = few_cycle_peak(detrend(x), 1.0)
        hits += p is not None and p.oscillating
    assert hits <= 1, hits


def test_few_cycle_test_finds_three_cycles_and_says_when_there_are_fewer() -> None:
    t = np.arange(900, dtype=np.float64)
    noise = 0.1 * np.random.default_rng(5).normal(size=t.size)
    three = few_cycle_peak(detrend(np.sin(2 * np.pi * t / 290.0) + noise), 1.0)
    assert three is not None and three.oscillating and 260 < three.period_s < 320
    two = few_cycle_peak(detrend(np.sin(2 * np.pi * t / 420.0) + noise), 1.0)
    assert two is not None and not two.oscillating
    assert two.reason.startswith("record too short to judge")
