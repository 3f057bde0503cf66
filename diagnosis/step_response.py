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
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import (
    FloatArray,
    first_order_recursions,
    moving_average,
    noise_sigma,
    sorted_unique,
)


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
    jump: float | None = None
    """Largest PV move over ``jump_horizon`` samples while the PV rose from 20 % to 63 % of the
    step (or to the next step, when it never reached 63 %), as a share of the step; None when
    the PV never reached 20 %."""
    op_pushes: bool | None = None
    """OP had moved, at the 63 % point (or the last sample before the next step), at least as
    far as its proportional kick, in the direction that moves the PV toward the new set point:
    the integral action kept pushing. None when OP was not given or the PV never reached
    20 %."""
    fitted: bool = False
    """Read by the least-squares fit (a step of 3-6 noise σ, ``fopdt_fit``) rather than
    through its 20 % and 63 % points."""

    @property
    def slowness(self) -> float:
        """τ_cl / θ (θ at least ``MIN_DEAD_TIME`` samples); a lower bound when PV never
        reached 63 %."""
        tau = self.time_constant if self.time_constant is not None else self.observed
        return tau / max(self.dead_time, MIN_DEAD_TIME)

    @property
    def settling(self) -> tuple[int, int]:
        """Samples [step, 95 % settled]: dead time and three closed-loop time constants, or
        the whole stretch to the next step when the PV never reached 63 %."""
        if self.time_constant is None:
            return self.start, self.start + self.dead_time + self.observed
        return self.start, self.start + self.dead_time + 3 * self.time_constant

    def creeps(self, slowness_limit: float, max_jump: float) -> bool:
        """A sluggish PI's answer: slower than ``slowness_limit`` dead times, OP pushing on
        past its kick, and the PV following without a jump of ``max_jump`` of the step."""
        return (
            self.slowness > slowness_limit
            and self.jump is not None
            and self.jump < max_jump
            and bool(self.op_pushes)
        )


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
    op: FloatArray | None = None,
    gain_sign: int = 1,
    jump_horizon: int = 8,
    min_fit_step_noise: float = 3.0,
) -> tuple[StepResponse, ...]:
    """The response of PV to each set-point step at sample indices ``steps``.

    A step counts when it is ``min_step_noise`` × the PV noise σ and ``min_samples`` follow it
    before the next step. The response is PV relative to its mean over the ``baseline``
    samples before the step, divided by the step and averaged over ``smooth`` samples; θ and
    τ_cl are those of the first order plus dead time through its 20 % and 63 % points
    (τ = (t63 − t20)/0.777, θ = t20 − 0.223·τ): robust to noise where the first visible move
    is not.

    With ``op`` (and the process gain's sign ``gain_sign``) each response also says how the PV
    rose (``jump``: its largest move over ``jump_horizon`` samples) and whether OP, averaged
    the same way, kept pushing past its proportional kick (``op_pushes``; the kick is read
    two samples after the step). That tells a sluggish PI's creep from a sticky valve's
    answer (``StepResponse.creeps``).

    Where no step stands ``min_step_noise`` σ clear, the steps of ``min_fit_step_noise`` σ
    and more are read by a least-squares fit of the same first order plus dead time to every
    sample of the response (``fopdt_fit``) instead: the two-point method reads single noisy
    crossings, the fit averages the noise over the whole response. Such a response has no
    ``jump`` or ``op_pushes`` (it never sets events aside).
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
        if t20.size == 0:
            out.append(StepResponse(k, size, 0, None, nxt - k, overshoot))
            continue
        i20 = int(t20[0])
        # the rise read to the 63 % point, or to the next step or the window's end
        i63 = int(t63[0]) if t63.size else y.size - 1
        rise = y[max(0, i20 - jump_horizon) : i63 + jump_horizon + 1]
        jump = (
            float(np.max(np.abs(rise[jump_horizon:] - rise[:-jump_horizon])))
            if rise.size > jump_horizon
            else None
        )
        pushes = None
        if op is not None:
            toward = gain_sign * np.sign(size)
            u = toward * (
                moving_average(op[k:nxt], smooth) - float(np.mean(op[max(0, k - baseline) : k]))
            )
            kick = float(u[min(2, u.size - 1)])
            pushes = bool(u[i63] > 0 and u[i63] >= kick)
        if t63.size == 0:
            out.append(StepResponse(k, size, i20, None, nxt - k - i20, overshoot, jump, pushes))
            continue
        # first order plus dead time through the 20 % and 63 % points (two-point method)
        tau = max(1, round((i63 - i20) / 0.777))
        theta = max(0, round(i20 - 0.223 * tau))
        out.append(StepResponse(k, size, theta, tau, nxt - k - theta, overshoot, jump, pushes))
    if out:
        return tuple(out)
    return _fitted_responses(pv, sp, steps, sigma, min_fit_step_noise, min_step_noise, min_samples)


FIT_BEFORE = 200
"""Samples before a set-point step (back to the previous step) that pin the fitted response's
starting level."""
FIT_LENGTH = 2000
"""Samples after a set-point step read by the fit at most."""
FIT_MAX_DEAD_TIME = 200
"""Longest dead time the fit tries, samples."""
FIT_GAIN = (0.5, 1.5)
"""A fitted response moves the PV by this share of the step (the integral action brings the
PV to the set point); outside, a load moved it as much as the step did and the fit is not
the step's."""
FIT_TIME_CONSTANTS = sorted_unique(np.round(np.logspace(0.0, np.log10(1500.0), 40)))
"""Closed-loop time constants the fit tries, samples (``sorted_unique``: ``np.unique``
imports ``numpy.ma``, 6-17 ms of every CLI start)."""


def fopdt_fit(y: FloatArray, start: int, max_dead_time: int) -> tuple[int, float, float, float]:
    """Least-squares first order plus dead time y ≈ c + K·(1 − e^{−(t − start − θ)/τ}) for
    t ≥ start + θ (c before), over every θ up to ``max_dead_time`` and τ of
    ``FIT_TIME_CONSTANTS``. Returns (θ samples, τ samples, K, c).

    For each τ the sums the least squares need come in closed form for every θ at once:
    Σx and Σx² are geometric series, and Σx·y = Σy − Z_θ with Z_θ = Σ_{t≥θ} r^{t−θ}·y_t
    (r = e^{−1/τ}) one backward first-order recursion over the response (Ljung 1999 on
    least squares over a grid of the nonlinear parameters; the two-point method is Smith's).
    """
    n = y.size
    m_after = n - start
    thetas = np.arange(0, min(max_dead_time, m_after // 2) + 1)
    r = np.exp(-1.0 / FIT_TIME_CONSTANTS)
    yr = y[start:][::-1]
    # Z[θ] for every θ: backward recursion z_k = y_k + r·z_{k+1}
    z = first_order_recursions(yr, r.tolist(), [1.0] * r.size)[:, ::-1][:, thetas]
    tail = np.concatenate((np.cumsum(yr)[::-1], [0.0]))[thetas]  # Σ_{t≥θ} y_t
    m = (m_after - thetas)[None, :].astype(np.float64)  # samples from θ on
    rr = r[:, None]
    geo = (1.0 - rr**m) / (1.0 - rr)
    sx = m - geo
    sxx = m - 2.0 * geo + (1.0 - rr ** (2.0 * m)) / (1.0 - rr * rr)
    sxy = tail[None, :] - z
    sy, syy = float(y.sum()), float(y @ y)
    cxx = sxx - sx * sx / n
    cxy = sxy - sx * sy / n
    with np.errstate(divide="ignore", invalid="ignore"):
        sse = np.where(cxx > 0, (syy - sy * sy / n) - cxy * cxy / cxx, np.inf)
    i, j = np.unravel_index(int(np.argmin(sse)), sse.shape)
    gain = float(cxy[i, j] / cxx[i, j]) if cxx[i, j] > 0 else 0.0
    level = (sy - gain * float(sx[i, j])) / n
    return int(thetas[j]), float(FIT_TIME_CONSTANTS[i]), gain, level


def _fitted_responses(
    pv: FloatArray,
    sp: FloatArray,
    steps: NDArray[np.int64],
    sigma: float,
    min_noise: float,
    max_noise: float,
    min_samples: int,
) -> tuple[StepResponse, ...]:
    """Steps of ``min_noise``-``max_noise`` σ read by ``fopdt_fit`` (see
    ``sp_step_responses``); the overshoot read on the response averaged over as many samples
    as bring its noise to a tenth of the step."""
    out: list[StepResponse] = []
    bounds = [0, *steps.tolist(), int(pv.size)]
    for prev, k, nxt in zip(bounds, bounds[1:], bounds[2:], strict=False):
        size = float(sp[k] - sp[k - 1]) if k > 0 else 0.0
        small = min_noise * sigma <= abs(size) < max_noise * sigma
        if k < 1 or nxt - k < 5 * min_samples or not small:
            continue
        lo = max(prev, k - FIT_BEFORE)
        y = (pv[lo : min(nxt, k + FIT_LENGTH)] - float(pv[k - 1])) / size
        theta, tau, gain, level = fopdt_fit(y, k - lo, FIT_MAX_DEAD_TIME)
        if not FIT_GAIN[0] <= gain <= FIT_GAIN[1]:
            continue
        after = y[k - lo :]
        width = max(1, math.ceil((10.0 * sigma / abs(size)) ** 2))
        overshoot = max(0.0, float(np.max(moving_average(after, width))) - level - 1.0)
        seen = theta + tau <= after.size
        out.append(
            StepResponse(
                k,
                size,
                theta,
                round(tau) if seen else None,
                nxt - k - theta,
                overshoot,
                fitted=True,
            )
        )
    return tuple(out)


def all_creep(responses: tuple[StepResponse, ...], slowness_limit: float, max_jump: float) -> bool:
    """Every set-point step in the window answered with a sluggish PI's creep, at least one of
    them seen to its 63 % point (one cut short by the next step is only part of a creep).

    A sluggish PI answers a step with a small proportional kick and then an integral action
    that keeps pushing OP the same way, and the PV follows smoothly, many dead times slow. A
    sticky valve answers with a slip (a jump), or, when the kick breaks it loose at once, it
    holds while OP turns back under the proportional action and the PV runs on through the
    process' own lag: OP then ends short of its kick. Where every step creeps, the loop's own
    answer says sluggish, whatever else the window holds [R, generated windows: see
    ``TuningParams.creep_max_jump``]."""
    return any(r.time_constant is not None for r in responses) and all(
        r.creeps(slowness_limit, max_jump) for r in responses
    )


def step_slowness(responses: tuple[StepResponse, ...]) -> float | None:
    """Median τ_cl/θ over the steps (None without any): about 1 for a loop tuned by SIMC;
    generated healthy loops 0.6-2.4, sluggish ones (gain × 0.2, integral time × 5) 3.2-350
    [R]."""
    if not responses:
        return None
    return float(np.median([r.slowness for r in responses]))
