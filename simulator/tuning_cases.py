"""Simulated loops with a known process and controller, for the identification and retuning
figures (issue 48): self-regulating first order plus dead time (τ 3-300 s, θ/τ 0.05-1.5,
gain 0.4-3 of either sign) or integrating (levels under tight control: their good tuning is
SIMC's τc = 1-1.5 θ, not an averaging one), sampled at a twentieth of their time
scale, tuned well (SIMC τc = 1-1.5 θ), sluggishly (τc = 4-10 θ) or aggressively (60-85 % of
the ultimate gain), with 1-4 set-point steps (or none: routine operation), measurement noise
and slow loads at the process input scaled by ``loads``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.identification import ProcessModel
from plantcheck.simulator.cases import simc_pi_tc, ultimate_gain
from plantcheck.simulator.loop import (
    Disturbance,
    LoopConfig,
    LoopRecord,
    PIController,
    Process,
    simulate_loop,
)

Tuning = Literal["good", "sluggish", "aggressive"]


@dataclass(frozen=True)
class TuningCase:
    """One simulated loop: its true process, sample time (s), controller and record."""

    process: Process
    ts: float
    controller: PIController
    record: LoopRecord

    @property
    def effective_dead_time_s(self) -> float:
        """The dead time the simulator applies: a whole number of samples."""
        return round(self.process.theta_s / self.ts) * self.ts

    @property
    def sp_steps(self) -> NDArray[np.int64]:
        """The samples where the set point steps."""
        return np.flatnonzero(np.diff(self.record.sp) != 0) + 1

    @property
    def loop_type(self) -> str:
        """``level`` for an integrating process, else ``flow``."""
        return "level" if self.process.kind == "integrating" else "flow"

    @property
    def level_control(self) -> Literal["averaging", "tight"]:
        """The level loops here are tuned for tight control (their good setting is SIMC's
        τc = 1-1.5 θ): a proposal for them is judged as one for tight control."""
        return "tight"

    def true_model(self) -> ProcessModel:
        """The process as the identification would state it, with the dead time applied."""
        integrating = self.process.kind == "integrating"
        return ProcessModel(
            kind="ipdt" if integrating else "fopdt",
            K=self.process.K,
            tau_s=None if integrating else self.process.tau_s,
            theta_s=self.effective_dead_time_s,
        )


def tuning_case(
    seed: int, tuning: Tuning = "good", loads: float = 0.3, sp_steps: bool = True
) -> TuningCase:
    """The loop of ``seed`` (reproducible), tuned as ``tuning`` says."""
    rng = np.random.default_rng(seed)
    if rng.random() < 0.25:
        proc = Process(
            kind="integrating",
            K=float(rng.uniform(0.005, 0.05)),
            theta_s=float(rng.uniform(1.0, 30.0)),
        )
        slow = 20.0 + 5.0 * proc.theta_s
    else:
        tau = float(np.exp(rng.uniform(math.log(3.0), math.log(300.0))))
        theta = float(tau * np.exp(rng.uniform(math.log(0.05), math.log(1.5))))
        gain = float(rng.uniform(0.4, 3.0) * rng.choice([-1.0, 1.0]))
        proc = Process(K=gain, tau_s=tau, theta_s=theta)
        slow = tau + theta
    ts = float(np.clip(round(slow / 20.0, 1), 0.1, 10.0))
    if tuning == "aggressive":
        base = simc_pi_tc(proc, 1.0)
        ku, _ = ultimate_gain(proc, base.Ti_s, ts)
        share = float(rng.uniform(0.6, 0.85))
        pi = PIController(Kc=share * ku * math.copysign(1.0, proc.K), Ti_s=base.Ti_s)
    else:
        lo, hi = (4.0, 10.0) if tuning == "sluggish" else (1.0, 1.5)
        pi = simc_pi_tc(proc, float(rng.uniform(lo, hi)))
    n = int(rng.integers(1500, 6000))
    duration = n * ts
    k = int(rng.integers(1, 5))
    times = np.sort(rng.uniform(0.1, 0.8, k)) * duration
    sps = tuple(
        (float(t), float(50.0 + rng.choice([-1.0, 1.0]) * rng.uniform(3.0, 10.0))) for t in times
    )
    load = Disturbance(
        where="load",
        filtered_noise_std=float(rng.uniform(0.0, 1.5)) * loads,
        filtered_noise_tau_s=2.0 * slow,
    )
    cfg = LoopConfig(
        process=proc,
        controller=pi,
        noise_std=float(rng.uniform(0.02, 0.3)),
        sp_steps=sps if sp_steps else (),
        sample_time_s=ts,
        n_samples=n,
        seed=seed,
        disturbances=(load,),
        warmup_samples=200,
    )
    return TuningCase(proc, ts, pi, simulate_loop(cfg))
