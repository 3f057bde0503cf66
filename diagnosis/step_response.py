"""Set-point step responses read from the data, for the tuning verdict (methods.md §3.3,
set-point response indices; issue 25 item 2).

A set-point step is the one experiment a running plant does for free. The closed-loop response
shows the loop's dead time θ (PV does not move before it) and its closed-loop time constant
τ_cl (from the first move to 63 % of the step). Well-tuned loops answer in about their own dead
time (SIMC, Skogestad 2003: τ_c = θ), whatever the process' own time constant; a sluggish
controller takes many dead times. Dividing by θ makes the index independent of the process
speed, so a healthy slow loop is not called sluggish. Times in samples unless named ``_s``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import FloatArray, moving_average, noise_sigma


@dataclass(frozen=True)
class StepResponse:
    """One set-point step and the PV's answer to it.

    ``dead_time`` and ``time_constant`` are in samples; ``time_constant`` is None when PV did
    not reach 63 % of the step before the next step or the window's end (then
    ``observed`` samples is a lower bound). ``overshoot`` is the largest excursion beyond the
    new set point as a share of the step.
    """

    start: int
    size: float
    dead_time: int
    time_constant: int | None
    observed: int
    overshoot: float

    @property
    def slowness(self) -> float:
        """τ_cl / θ (θ at least ``MIN_DEAD_TIME`` samples); a lower bound when PV never
        reached 63 %."""
        tau = self.time_constant if self.time_constant is not None else self.observed
        return tau / max(self.dead_time, MIN_DEAD_TIME)


MIN_DEAD_TIME = 2
"""Samples: a dead time read below this is the sampling's resolution, not the loop's."""


def sp_step_responses(
    pv: FloatArray,
    sp: FloatArray,
    steps: NDArray[np.int64],
    *,
    min_samples: int = 20,
    min_step_noise: float = 6.0,
    baseline: int = 5,
    smooth: int = 5,
) -> tuple[StepResponse, ...]:
    """The response of PV to each set-point step at sample indices ``steps``.

    A step counts when it is ``min_step_noise`` × the PV noise σ and ``min_samples`` follow it
    before the next step. The response is PV relative to its mean over the ``baseline``
    samples before the step, divided by the step and averaged over ``smooth`` samples; θ and
    τ_cl are those of the first order plus dead time through its 20 % and 63 % points
    (τ = (t63 − t20)/0.777, θ = t20 − 0.223·τ): robust to noise where the first visible move
    is not.
    """
    sigma = noise_sigma(pv)
    out: list[StepResponse] = []
    bounds = [*steps.tolist(), int(pv.size)]
    for k, nxt in itertools.pairwise(bounds):
        size = float(sp[k] - sp[k - 1]) if k > 0 else 0.0
        if nxt - k < min_samples or k < 1 or abs(size) < min_step_noise * sigma:
            continue
        before = pv[max(0, k - baseline) : k]
        y = moving_average((pv[k:nxt] - float(np.mean(before))) / size, smooth)
        t20 = np.flatnonzero(y >= 0.2)
        t63 = np.flatnonzero(y >= 0.63)
        overshoot = max(0.0, float(np.max(y)) - 1.0)
        if t20.size == 0 or t63.size == 0:
            start = int(t20[0]) if t20.size else 0
            out.append(StepResponse(k, size, start, None, nxt - k - start, overshoot))
            continue
        # first order plus dead time through the 20 % and 63 % points (two-point method)
        tau = max(1, round((int(t63[0]) - int(t20[0])) / 0.777))
        theta = max(0, round(int(t20[0]) - 0.223 * tau))
        out.append(StepResponse(k, size, theta, tau, nxt - k - theta, overshoot))
    return tuple(out)


def step_slowness(responses: tuple[StepResponse, ...]) -> float | None:
    """Median τ_cl/θ over the steps (None without any): about 1 for a loop tuned by SIMC;
    generated healthy loops 0.6-2.4, sluggish ones (gain × 0.2, integral time × 5) 3.2-350
    [R]."""
    if not responses:
        return None
    return float(np.median([r.slowness for r in responses]))
