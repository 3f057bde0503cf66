"""Load-disturbance recoveries read from the data, for the tuning verdict (issue 25 item 2).

A load step is the other experiment a running plant does for free. The control error leaves
zero as fast as the process lets it (its *departure*, onset to peak, is set by the process'
dead time and lag, which the controller cannot hasten), then the controller brings it back
(its *recovery*, peak to 37 % of the peak). A well-tuned PI loop recovers in about the time
the load took to push the error out; a sluggish one (too little gain, too long an integral
time) takes many times longer, and its output creeps monotonically all the while. The ratio
recovery / departure is dimensionless and independent of the process' speed, so a healthy slow
loop is not called sluggish: the same idea as the set-point step slowness
(``step_response.step_slowness``), and the reading Hägglund's idle index (Hägglund 1999, CEP
7:1505) and Visioli's area index (Visioli 2005, IEE Proc. CTA 152:1) make of load responses,
measured here on the error's own time scale instead of from signs of increments, which noise
swamps in a slow loop. Times in samples.

An integrating (level) process has no departure of its own (the error ramps until the
controller stops it), so the ratio does not apply there; a sticky valve recovers in one slip,
faster than it departed, which keeps the ratio low.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.peaks import prominent_extremes
from plantcheck.diagnosis.signal_tools import FloatArray, moving_average, noise_sigma


@dataclass(frozen=True)
class LoadRecovery:
    """One load response of the control error: onset, peak and the sample where it is back to
    ``recovered_fraction`` of its peak; the peak in noise σ of the smoothed error."""

    onset: int
    peak: int
    recovered: int
    peak_sigma: float

    @property
    def slowness(self) -> float:
        """Recovery time over departure time (departure at least ``MIN_DEPARTURE`` samples)."""
        return (self.recovered - self.peak) / max(self.peak - self.onset, MIN_DEPARTURE)


MIN_DEPARTURE = 2
"""Samples: a departure read below this is the sampling's resolution, not the process'."""


def load_recoveries(
    pv: FloatArray,
    sp: FloatArray,
    steps: NDArray[np.int64],
    *,
    smooth: int = 5,
    min_peak_sigma: float = 8.0,
    onset_fraction: float = 0.1,
    recovered_fraction: float = 0.37,
    step_guard: int = 5,
    max_responses: int = 16,
) -> tuple[LoadRecovery, ...]:
    """The load responses of the control error e = SP − PV in one window.

    Parameters
    ----------
    pv, sp:
        Process variable and set point, engineering units, no NaN.
    steps:
        Sample indices of set-point steps; a response that a step starts or interrupts
        (within ``step_guard`` samples before its onset, or before it has recovered) is the
        step's, not a load's, and is left out.
    smooth:
        Centred moving average of e, samples, before its peaks are read.
    min_peak_sigma:
        A response peaks at least this many σ of the smoothed error's noise away from zero
        (and with that prominence) [R].
    onset_fraction, recovered_fraction:
        The onset is the last sample before the peak with |e| below this share of the peak;
        the recovery the first after it below ``recovered_fraction`` (1/e, a time constant).
    max_responses:
        Only the largest responses are read.
    """
    e = moving_average(sp - pv, smooth)
    sigma = max(noise_sigma(pv) / np.sqrt(max(smooth, 1)), 1e-12)
    floor = min_peak_sigma * sigma
    highs, lows = prominent_extremes(e, floor)
    peaks = np.concatenate((highs, lows))
    signs = np.concatenate((np.ones(highs.size), -np.ones(lows.size)))
    tops = signs * e[peaks]
    keep = np.flatnonzero(tops >= floor)
    # the largest responses say it: a day-long noisy window has hundreds of small ones
    keep = keep[np.argsort(-tops[keep], kind="stable")][:max_responses]
    out: list[LoadRecovery] = []
    for p, sign, top in zip(peaks[keep].tolist(), signs[keep], tops[keep].tolist(), strict=True):
        x = sign * e
        before = np.flatnonzero(x[:p] < onset_fraction * top)
        after = np.flatnonzero(x[p:] < recovered_fraction * top)
        if before.size == 0 or after.size == 0:
            continue
        onset, recovered = int(before[-1]), p + int(after[0])
        if np.any((steps > onset - step_guard) & (steps <= recovered)):
            continue
        out.append(LoadRecovery(onset, p, recovered, top / sigma))
    return tuple(sorted(out, key=lambda r: r.peak))


def recovery_slowness(recoveries: tuple[LoadRecovery, ...]) -> float | None:
    """Median recovery / departure over the load responses (None without any); the figures
    per class are in ``TuningParams.load_recovery_limit``."""
    if not recoveries:
        return None
    return float(np.median([r.slowness for r in recoveries]))
