"""Single closed control loop: process, PI controller, valve, disturbance and noise.

Fixed-step simulation with exact (zero-order-hold) discretisation of the process:

- self-regulating first order plus dead time, K·e^{-θs}/(τs + 1), optionally a second lag;
- integrating, K·e^{-θs}/s.

Disturbances enter at the process input (load) and/or the process output (measured PV),
measurement noise is added to the PV that the controller sees. Everything is in % of span.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from plantcheck.simulator.actuator import ActuatorSpec
from plantcheck.simulator.valves import HeValve, KanoValve, LinearValve, Valve

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Process:
    """Process dynamics from valve position (% travel) to PV (% of span).

    ``kind`` is ``"fopdt"`` (gain K, time constant tau_s, dead time theta_s, optional second
    time constant tau2_s) or ``"integrating"`` (K in %/s per % of travel, dead time theta_s).
    """

    kind: Literal["fopdt", "integrating"] = "fopdt"
    K: float = 1.0
    tau_s: float = 10.0
    theta_s: float = 2.0
    tau2_s: float = 0.0


@dataclass(frozen=True)
class PIController:
    """Positional PI controller with output limits and clamping anti-windup.

    u = bias + Kc·(e + (1/Ti)∫e dt), e = SP − PV; Kc < 0 gives direct action.
    """

    Kc: float = 1.0
    Ti_s: float = 10.0
    op_min: float = 0.0
    op_max: float = 100.0


@dataclass(frozen=True)
class Disturbance:
    """Load (process input) and output disturbances.

    ``sine_amplitude`` (% of span at the output, or % of travel at the load) with period
    ``sine_period_s``; ``random_walk_std`` per sqrt(second); ``steps``: (time_s, size) pairs;
    ``filtered_noise_std`` with time constant ``filtered_noise_tau_s``.
    """

    where: Literal["load", "output"] = "load"
    sine_amplitude: float = 0.0
    sine_period_s: float = 100.0
    random_walk_std: float = 0.0
    filtered_noise_std: float = 0.0
    filtered_noise_tau_s: float = 20.0
    steps: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class LoopConfig:
    """Everything that defines one simulated loop run."""

    process: Process = field(default_factory=Process)
    controller: PIController = field(default_factory=PIController)
    valve: Literal["linear", "kano", "he"] = "linear"
    S: float = 0.0
    J: float = 0.0
    disturbances: tuple[Disturbance, ...] = ()
    noise_std: float = 0.0
    sp: float = 50.0
    sp_steps: tuple[tuple[float, float], ...] = ()
    u0: float = 50.0
    sample_time_s: float = 1.0
    n_samples: int = 3600
    warmup_samples: int = 0
    seed: int = 0
    actuator: ActuatorSpec | None = None
    """Positioner and actuator fault between OP and the stem; None: the stem is the valve."""
    mv_noise_std: float = 0.0
    """Measurement noise of the stem position sensor, % of travel."""


@dataclass(frozen=True)
class LoopRecord:
    """Simulated signals, one value per sample (time in seconds, signals in %)."""

    t: FloatArray
    sp: FloatArray
    pv: FloatArray
    op: FloatArray
    mv: FloatArray


def make_valve(cfg: LoopConfig) -> Valve:
    """Build the valve model named in ``cfg`` (S, J in % of travel)."""
    if cfg.valve == "kano":
        return KanoValve(S=cfg.S, J=cfg.J)
    if cfg.valve == "he":
        # He model parameters from (S, J): S = fs + fd, J = fs - fd.
        return HeValve(fs=(cfg.S + cfg.J) / 2.0, fd=(cfg.S - cfg.J) / 2.0)
    return LinearValve()


def _disturbance_signal(d: Disturbance, t: FloatArray, rng: np.random.Generator) -> FloatArray:
    ts = float(t[1] - t[0]) if t.size > 1 else 1.0
    out = np.zeros_like(t)
    if d.sine_amplitude:
        phase = rng.uniform(0, 2 * math.pi)
        out += d.sine_amplitude * np.sin(2 * math.pi * t / d.sine_period_s + phase)
    if d.random_walk_std:
        out += np.cumsum(rng.normal(0.0, d.random_walk_std * math.sqrt(ts), t.size))
    if d.filtered_noise_std:
        a = math.exp(-ts / d.filtered_noise_tau_s)
        w = rng.normal(0.0, d.filtered_noise_std * math.sqrt(1 - a * a), t.size)
        x = np.empty_like(t)
        acc = 0.0
        for k in range(t.size):
            acc = a * acc + w[k]
            x[k] = acc
        out += x
    for t_step, size in d.steps:
        out += np.where(t >= t_step, size, 0.0)
    return out


def simulate_loop(cfg: LoopConfig) -> LoopRecord:
    """Simulate one closed loop and return the last ``n_samples`` samples after warm-up."""
    rng = np.random.default_rng(cfg.seed)
    ts = cfg.sample_time_s
    n_total = cfg.n_samples + cfg.warmup_samples
    t = np.arange(n_total, dtype=np.float64) * ts
    load = np.zeros(n_total)
    out_d = np.zeros(n_total)
    for d in cfg.disturbances:
        sig = _disturbance_signal(d, t, rng)
        if d.where == "load":
            load += sig
        else:
            out_d += sig
    noise = rng.normal(0.0, cfg.noise_std, n_total) if cfg.noise_std else np.zeros(n_total)
    sp = np.full(n_total, cfg.sp)
    for t_step, value in cfg.sp_steps:
        sp[t >= t_step + cfg.warmup_samples * ts] = value

    p = cfg.process
    c = cfg.controller
    valve: Valve = make_valve(cfg)
    if cfg.actuator is not None:
        valve = cfg.actuator.build(valve, ts)
    delay = max(0, round(p.theta_s / ts))
    queue: deque[float] = deque([cfg.u0] * delay, maxlen=delay) if delay else deque()
    a1 = math.exp(-ts / p.tau_s) if p.kind == "fopdt" else 1.0
    a2 = math.exp(-ts / p.tau2_s) if p.tau2_s > 0 else 0.0
    x1 = 0.0  # deviation states around the initial valve position u0
    x2 = 0.0
    y0 = cfg.sp
    integral = cfg.u0  # integral part of the positional PI, starts at the bias
    pv = np.empty(n_total)
    op = np.empty(n_total)
    mv = np.empty(n_total)
    for k in range(n_total):
        y = y0 + (x2 if p.tau2_s > 0 else x1) + out_d[k]
        pv_meas = y + noise[k]
        e = sp[k] - pv_meas
        u_unsat = integral + c.Kc * e
        u = min(max(u_unsat, c.op_min), c.op_max)
        # clamping anti-windup: integrate only when not pushing further into a limit
        if (
            u == u_unsat
            or (u_unsat > c.op_max and e * c.Kc < 0)
            or (u_unsat < c.op_min and e * c.Kc > 0)
        ):
            integral += c.Kc * ts / c.Ti_s * e
        m = valve.step(u)
        pv[k], op[k], mv[k] = pv_meas, u, m
        u_in = m - cfg.u0 + load[k]
        if delay:
            u_del = queue[0] - cfg.u0 + load[k]
            queue.append(m)
        else:
            u_del = u_in
        if p.kind == "fopdt":
            x1 = a1 * x1 + p.K * (1 - a1) * u_del
            if p.tau2_s > 0:
                x2 = a2 * x2 + (1 - a2) * x1
        else:
            x1 = x1 + p.K * ts * u_del
    if cfg.mv_noise_std:
        mv = mv + rng.normal(0.0, cfg.mv_noise_std, n_total)
    keep = slice(cfg.warmup_samples, n_total)
    return LoopRecord(
        t=t[keep] - t[cfg.warmup_samples],
        sp=sp[keep],
        pv=pv[keep],
        op=op[keep],
        mv=mv[keep],
    )
