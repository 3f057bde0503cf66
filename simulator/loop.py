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
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from itertools import pairwise
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from plantcheck.simulator.actuator import ActuatorSpec
from plantcheck.simulator.valves import (
    BacklashValve,
    ChoudhuryValve,
    DriftingFriction,
    HeValve,
    KanoValve,
    LinearValve,
    Valve,
)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Process:
    """Process dynamics from valve position (% travel) to PV (% of span).

    ``kind`` is ``"fopdt"`` (gain K, time constant tau_s, dead time theta_s, optional second
    time constant tau2_s) or ``"integrating"`` (K in %/s per % of travel, dead time theta_s).
    ``zero_s`` (s) puts a zero (1 + zero_s·s) on a second-order process: negative, a
    right-half-plane zero, is an inverse response (a drum level's swell, Åström & Hägglund 1995).
    """

    kind: Literal["fopdt", "integrating"] = "fopdt"
    K: float = 1.0
    tau_s: float = 10.0
    theta_s: float = 2.0
    tau2_s: float = 0.0
    zero_s: float = 0.0


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
    ``sine_period_s``, its waveform ``shape``; ``random_walk_std`` per sqrt(second); ``steps``:
    (time_s, size) pairs; ``filtered_noise_std`` with time constant ``filtered_noise_tau_s``.
    """

    where: Literal["load", "output"] = "load"
    sine_amplitude: float = 0.0
    sine_period_s: float = 100.0
    shape: Literal["sine", "square", "triangle"] = "sine"
    """The periodic load's waveform, twice ``sine_amplitude`` from trough to peak, about a
    zero mean: ``square``, a sticky valve or an on/off unit upstream jumping between two
    positions (high for ``duty`` of each period); ``triangle``, a level or an integral action
    upstream ramping between them (rising for ``duty`` of each period); each through a
    first-order lag of ``edge_lag_s``, the process between. A plant's periodic loads are more
    often another loop's limit cycle than a sine (Thornhill & Horch 2007)."""
    duty: float = 0.5
    edge_lag_s: float = 0.0
    random_walk_std: float = 0.0
    filtered_noise_std: float = 0.0
    filtered_noise_tau_s: float = 20.0
    steps: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        if not 0.0 < self.duty < 1.0:
            raise ValueError(f"duty: {self.duty}; give the share of a period, between 0 and 1")
        if self.edge_lag_s < 0.0:
            raise ValueError(f"edge_lag_s: {self.edge_lag_s}; give a lag of 0 s or more")


FlowCharacteristic = Literal["linear", "equal_percentage", "quick_opening"]
"""A valve's inherent flow characteristic (``LoopConfig.characteristic``)."""


@dataclass(frozen=True)
class LoopConfig:
    """Everything that defines one simulated loop run."""

    process: Process = field(default_factory=Process)
    controller: PIController = field(default_factory=PIController)
    valve: Literal["linear", "kano", "he", "choudhury", "backlash"] = "linear"
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
    friction_spread: float = 0.0
    """A sticky valve's friction varies from stop to stop by exp(this × N(0, 1))
    (``valves.DriftingFriction``); 0: the same band at every stop."""
    pv_quantum: float = 0.0
    """Resolution of the recorded PV (transmitter or historian steps), % of span; 0: none."""
    pv_compression: float = 0.0
    """Historian compression deadband of the recorded PV, % of span: a value is stored only
    when it differs from the last stored one by more than this (the record holds the last
    stored value); 0: none. The controller sees the uncompressed PV."""
    interpolated: bool = False
    """The historian's export interpolates linearly between stored values (as PI and most
    process historians do when asked for values at a fixed interval) instead of holding."""
    op_compression: float = 0.0
    """Compression deadband of the recorded OP, % of travel (0: none)."""
    pv_filter_s: float = 0.0
    """Transmitter damping / DCS PV filter time constant (s): the controller and the record
    see the filtered measurement (0: none)."""
    characteristic: FlowCharacteristic = "linear"
    """The valve's inherent flow characteristic, scaled to slope 1 at ``u0`` (so a tuning for
    the linear loop holds at the operating point and the gain changes away from it)."""
    rangeability: float = 30.0
    """Equal-percentage rangeability R: flow ∝ R^(x/100 - 1)."""
    manual: tuple[tuple[float, float], ...] = ()
    """Stretches (start, end) of the record, s from its first sample after warm-up, in which
    an operator held the loop in manual: OP keeps its last value, the loads move PV unopposed,
    and the controller takes over from that value at the end (``ClosedLoop.auto``). Plants switch
    loops to manual for hours at a time, most often without a mode tag in the historian
    (issue 46 item 1); ``manual_mask`` says which samples they cover."""
    frozen_pv: tuple[tuple[float, float], ...] = ()
    """Stretches (start, end), s as ``manual``, in which the transmitter froze at its last
    reading: the controller and the record see that value, and the controller ramps OP on
    the constant error it makes (``ClosedLoop.frozen_pv``; Thornhill & Horch 2007 name a
    failed measurement held by the DCS among the faults that look like a loop's)."""

    def __post_init__(self) -> None:
        for name in ("manual", "frozen_pv"):
            stretches = getattr(self, name)
            end = 0.0
            for start, stop in stretches:
                if not end <= start < stop:
                    raise ValueError(
                        f"{name}: {stretches}; give (start, end) pairs in seconds of the "
                        "record, each starting at 0 or later, before its end and after the "
                        "previous one's end"
                    )
                end = stop


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
    sticky: KanoValve | HeValve | ChoudhuryValve | BacklashValve
    if cfg.valve == "kano":
        sticky = KanoValve(S=cfg.S, J=cfg.J)
    elif cfg.valve == "he":
        # He model parameters from (S, J): S = fs + fd, J = fs - fd.
        sticky = HeValve(fs=(cfg.S + cfg.J) / 2.0, fd=(cfg.S - cfg.J) / 2.0)
    elif cfg.valve == "choudhury":
        sticky = ChoudhuryValve(S=cfg.S, J=cfg.J)
    elif cfg.valve == "backlash":
        sticky = BacklashValve(d=cfg.S)
    else:
        return LinearValve()
    if cfg.friction_spread > 0.0:
        return DriftingFriction(sticky, cfg.friction_spread, seed=cfg.seed + 1)
    return sticky


def _disturbance_signal(d: Disturbance, t: FloatArray, rng: np.random.Generator) -> FloatArray:
    ts = float(t[1] - t[0]) if t.size > 1 else 1.0
    out = np.zeros_like(t)
    if d.sine_amplitude:
        phase = rng.uniform(0, 2 * math.pi)
        if d.shape == "sine":
            out += d.sine_amplitude * np.sin(2 * math.pi * t / d.sine_period_s + phase)
        else:
            out += d.sine_amplitude * _limit_cycle(d, t, phase / (2 * math.pi))
    if d.random_walk_std:
        out += np.cumsum(rng.normal(0.0, d.random_walk_std * math.sqrt(ts), t.size))
    if d.filtered_noise_std:
        a = math.exp(-ts / d.filtered_noise_tau_s)
        w = rng.normal(0.0, d.filtered_noise_std * math.sqrt(1 - a * a), t.size)
        # imported here: scipy.signal is 1-2 s of every process that imports the simulator,
        # and the served plant (simulator.plant) filters its own noise sample by sample
        from scipy.signal import lfilter

        # x[k] = a·x[k-1] + w[k], the same sums in the same order as a loop would make them
        out += lfilter([1.0], [1.0, -a], w)
    times = np.array([step[0] for step in d.steps])
    if d.steps and not out.any() and np.all(times[1:] >= times[:-1]):
        # steps alone, in time order (every corpus load made of steps): each sample holds the
        # running sum of the sizes reached, the sums the loop below makes in the same order
        # (np.cumsum adds one after another), without a pass over the record per step
        reached = np.searchsorted(times, t, side="right")
        sums = np.concatenate(([0.0], np.cumsum([step[1] for step in d.steps])))
        return sums[reached]
    for t_step, size in d.steps:
        out += np.where(t >= t_step, size, 0.0)
    return out


def _limit_cycle(d: Disturbance, t: FloatArray, phase: float) -> FloatArray:
    """A square or triangular wave (``Disturbance.shape``) 2 from trough to peak about a zero
    mean, at ``phase`` (cycles) when t = 0, through a first-order lag of ``edge_lag_s``
    started at its first value."""
    at = (t / d.sine_period_s + phase) % 1.0
    high = at < d.duty
    if d.shape == "square":
        wave = np.where(high, 1.0, -1.0) - (2.0 * d.duty - 1.0)
    else:
        wave = np.where(high, -1.0 + 2.0 * at / d.duty, 1.0 - 2.0 * (at - d.duty) / (1.0 - d.duty))
    if d.edge_lag_s <= 0.0 or t.size < 2:
        return np.asarray(wave, dtype=np.float64)
    a = math.exp(-float(t[1] - t[0]) / d.edge_lag_s)
    from scipy.signal import lfilter  # imported here, as for the filtered noise above

    lagged, _ = lfilter([1.0 - a], [1.0, -a], wave, zi=[a * float(wave[0])])
    return np.asarray(lagged, dtype=np.float64)


def delay_samples(p: Process, ts: float) -> int:
    """The process' dead time in whole samples of ``ts`` (s), as the loop's queue holds it."""
    return max(0, round(p.theta_s / ts))


class ClosedLoop:
    """One closed loop advanced a sample at a time: PI controller → actuator/valve → process.

    The process is discretised exactly under a zero-order hold (first or second order lag plus
    dead time, or integrator plus dead time); the PI controller is positional with clamping
    anti-windup. States are deviations around the initial valve position ``u0`` (% of travel)
    and the initial set point ``sp`` (% of span). ``simulate_loop`` and the live simulator
    (``plant.py``) both step this class, so batch records and served signals are the same model.
    """

    def __init__(self, cfg: LoopConfig) -> None:
        self.cfg = cfg
        ts = cfg.sample_time_s
        p = cfg.process
        valve: Valve = make_valve(cfg)
        if cfg.actuator is not None:
            valve = cfg.actuator.build(valve, ts)
        self.valve = valve
        self.delay = delay_samples(p, ts)
        self.queue: deque[float] = (
            deque([cfg.u0] * self.delay, maxlen=self.delay) if self.delay else deque()
        )
        self.a1 = math.exp(-ts / p.tau_s) if p.kind == "fopdt" else 1.0
        self.a2 = math.exp(-ts / p.tau2_s) if p.tau2_s > 0 else 0.0
        self.x1 = 0.0
        self.x2 = 0.0
        self.integral = cfg.u0  # integral part of the positional PI, starts at the bias
        self.auto = True
        self.frozen_pv: float | None = None
        """A transmitter frozen at this value (% of span): the controller and the record see
        it instead of the process (None: a live measurement)."""
        self.a_filter = math.exp(-ts / cfg.pv_filter_s) if cfg.pv_filter_s > 0 else 0.0
        self.pv_filtered: float | None = None

    def set_controller(self, Kc: float, Ti_s: float) -> None:
        """New PI settings from the next sample on; the integral state carries the output
        over, so only the proportional term's change moves OP (a retuning on line)."""
        c = replace(self.cfg.controller, Kc=Kc, Ti_s=Ti_s)
        self.cfg = replace(self.cfg, controller=c)

    def step(
        self, sp: float, load: float = 0.0, out_d: float = 0.0, noise: float = 0.0
    ) -> tuple[float, float, float]:
        """Advance one sample; return the measured PV, the controller output OP and the stem
        position MV (PV in % of span, OP and MV in % of travel).

        ``load`` enters at the process input (% of travel), ``out_d`` at the output (% of span),
        ``noise`` is the measurement noise on PV. In manual (``auto`` False) OP holds.
        """
        pv, op, mv = self.run([sp], [load], [out_d], [noise])
        return pv[0], op[0], mv[0]

    def run(
        self, sp: list[float], load: list[float], out_d: list[float], noise: list[float]
    ) -> tuple[list[float], list[float], list[float]]:
        """Advance ``len(sp)`` samples (``step``'s inputs and outputs, one list entry per
        sample; ``auto`` and the controller settings hold throughout). The loop keeps its
        states in local names: a corpus window and its twin are tens of thousands of samples
        each, and Python's attribute look-ups were most of their simulation's time."""
        cfg = self.cfg
        p = cfg.process
        c = cfg.controller
        ts = cfg.sample_time_s
        kc, op_min, op_max, u0, sp0 = c.Kc, c.op_min, c.op_max, cfg.u0, cfg.sp
        ki = c.Kc * ts / c.Ti_s
        auto, delay, queue, valve_step = self.auto, self.delay, self.queue, self.valve.step
        fopdt, lag2, zero = p.kind == "fopdt", p.tau2_s > 0, p.zero_s
        a1, a2, tau2 = self.a1, self.a2, p.tau2_s
        b1, b2, b_int = p.K * (1 - a1), 1 - a2, p.K * ts
        a_filter, pv_filtered, frozen = self.a_filter, self.pv_filtered, self.frozen_pv
        x1, x2, integral = self.x1, self.x2, self.integral
        flow = _flow_characteristic(cfg)
        pvs: list[float] = []
        ops: list[float] = []
        mvs: list[float] = []
        for sp_k, load_k, out_k, noise_k in zip(sp, load, out_d, noise, strict=True):
            # the true process value: (1 + z·s)·x2 with dx2/dt = (x1 - x2)/tau2, the zero
            # read off the second lag's state
            y = (x2 + zero * (x1 - x2) / tau2 if zero else x2) if lag2 else x1
            pv_meas = sp0 + y + out_k + noise_k
            if a_filter:
                prev = pv_meas if pv_filtered is None else pv_filtered
                pv_meas = pv_filtered = a_filter * prev + (1.0 - a_filter) * pv_meas
            if frozen is not None:
                pv_meas = frozen
            e = sp_k - pv_meas
            if auto:
                u_unsat = integral + kc * e
                u = min(max(u_unsat, op_min), op_max)
                # clamping anti-windup: integrate only when not pushing further into a limit
                if (
                    u == u_unsat
                    or (u_unsat > op_max and e * kc < 0)
                    or (u_unsat < op_min and e * kc > 0)
                ):
                    integral += ki * e
            else:  # manual: OP frozen at its last value; bumpless return to auto
                u = min(max(integral, op_min), op_max)
            m = valve_step(u)
            q = flow(m) if flow is not None else m
            if delay:
                u_del = queue[0] - u0 + load_k
                queue.append(q)
            else:
                u_del = q - u0 + load_k
            if fopdt:
                x1 = a1 * x1 + b1 * u_del
                if lag2:
                    x2 = a2 * x2 + b2 * x1
            else:
                x1 = x1 + b_int * u_del
            pvs.append(pv_meas)
            ops.append(u)
            mvs.append(m)
        self.x1, self.x2, self.integral, self.pv_filtered = x1, x2, integral, pv_filtered
        return pvs, ops, mvs


def _flow_characteristic(cfg: LoopConfig) -> Callable[[float], float] | None:
    """The process input (% of travel equivalent) for a stem position: the valve's inherent
    characteristic, shifted and scaled to pass through ``u0`` with slope 1; None when linear."""
    u0 = cfg.u0
    if cfg.characteristic == "equal_percentage":
        log_r = math.log(cfg.rangeability)
        scale = 100.0 / log_r

        def eq(x: float) -> float:
            return u0 + scale * (math.exp(log_r * (x - u0) / 100.0) - 1.0)

        return eq
    if cfg.characteristic == "quick_opening":
        root = math.sqrt(max(u0, 1.0))

        def quick(x: float) -> float:
            return u0 + 2.0 * root * (math.sqrt(max(x, 0.0)) - root)

        return quick
    return None


def recorded_pv(
    pv: FloatArray, quantum: float = 0.0, compression: float = 0.0, interpolated: bool = False
) -> FloatArray:
    """The PV as a historian returns it: rounded to ``quantum`` and held while it stays within
    ``compression`` of the last stored value (deadband compression), both % of span; with
    ``interpolated`` the export draws straight lines between the stored values."""
    out = np.round(pv / quantum) * quantum if quantum > 0 else pv.copy()
    if compression > 0 and out.size:
        # on Python floats: the same arithmetic, without a numpy scalar per sample
        values = out.tolist()
        held = values[0]
        stored = [0]
        for k, value in enumerate(values):
            if abs(value - held) > compression:
                held = value
                stored.append(k)
            values[k] = held
        out = np.array(values, dtype=np.float64)
        if interpolated:
            if stored[-1] != out.size - 1:
                stored.append(out.size - 1)
            idx = np.array(stored)
            out = np.interp(np.arange(out.size), idx, out[idx])
    return out


def simulate_loop(cfg: LoopConfig) -> LoopRecord:
    """Simulate one closed loop and return the last ``n_samples`` samples after warm-up."""
    rng, t, sp, load, out_d, noise = loop_inputs(cfg)
    if cfg.manual or cfg.frozen_pv:
        pv, op, mv = _run_stretches(cfg, sp, load, out_d, noise)
    else:
        runs = ClosedLoop(cfg).run(sp.tolist(), load.tolist(), out_d.tolist(), noise.tolist())
        pv, op, mv = (np.array(v, dtype=np.float64) for v in runs)
    return loop_record(cfg, rng, t, sp, pv, op, mv)


def stretch_samples(cfg: LoopConfig, stretches: tuple[tuple[float, float], ...]) -> BoolArray:
    """Which samples of a run, warm-up included, ``stretches`` (s of the record) cover."""
    n_total = cfg.n_samples + cfg.warmup_samples
    k = np.arange(n_total) - cfg.warmup_samples
    ts = cfg.sample_time_s
    inside = np.zeros(n_total, dtype=bool)
    for start, stop in stretches:
        inside |= (k >= math.ceil(start / ts - 1e-9)) & (k < math.ceil(stop / ts - 1e-9))
    return inside


def manual_mask(cfg: LoopConfig) -> BoolArray:
    """True on the record's samples (after warm-up) in which the loop is in manual
    (``LoopConfig.manual``): what a historian's mode tag would say, where a plant keeps one."""
    return stretch_samples(cfg, cfg.manual)[cfg.warmup_samples :]


def _run_stretches(
    cfg: LoopConfig, sp: FloatArray, load: FloatArray, out_d: FloatArray, noise: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``ClosedLoop.run`` over the run's inputs, switching to manual and freezing the
    transmitter at the last reading over ``cfg.manual`` and ``cfg.frozen_pv``."""
    manual = stretch_samples(cfg, cfg.manual)
    frozen = stretch_samples(cfg, cfg.frozen_pv)
    state = manual.astype(np.int8) * 2 + frozen
    cuts = [0, *(np.flatnonzero(np.diff(state)) + 1).tolist(), state.size]
    loop = ClosedLoop(cfg)
    pv: list[float] = []
    op: list[float] = []
    mv: list[float] = []
    for a, b in pairwise(cuts):
        loop.auto = not manual[a]
        if not loop.auto and op:  # the operator takes over the last output, which ``run``
            loop.integral = op[-1]  # holds through the integral state
        if not frozen[a]:
            loop.frozen_pv = None
        elif loop.frozen_pv is None:  # frozen at the last reading (the first: the set point)
            loop.frozen_pv = pv[-1] if pv else cfg.sp
        part = loop.run(sp[a:b].tolist(), load[a:b].tolist(), out_d[a:b].tolist(),
                        noise[a:b].tolist())  # fmt: skip
        pv += part[0]
        op += part[1]
        mv += part[2]
    return (np.array(pv, dtype=np.float64), np.array(op, dtype=np.float64),
            np.array(mv, dtype=np.float64))  # fmt: skip


def simulate_retuned_loop(cfg: LoopConfig, at: int, kc: float, ti_s: float) -> LoopRecord:
    """``simulate_loop(cfg)`` with the PI settings ``kc`` and ``ti_s`` (s) typed in from
    sample ``at`` of the record on (after warm-up; ``ClosedLoop.set_controller``: the integral
    state carries OP over, as a DCS does): a retuning inside the window."""
    if cfg.manual or cfg.frozen_pv:
        raise ValueError(
            "manual, frozen_pv: a retuned run takes neither; simulate the stretches with "
            "simulate_loop"
        )
    rng, t, sp, load, out_d, noise = loop_inputs(cfg)
    loop = ClosedLoop(cfg)
    cut = min(max(cfg.warmup_samples + at, 0), t.size)
    first = loop.run(sp[:cut].tolist(), load[:cut].tolist(), out_d[:cut].tolist(),
                     noise[:cut].tolist())  # fmt: skip
    loop.set_controller(kc, ti_s)
    rest = loop.run(sp[cut:].tolist(), load[cut:].tolist(), out_d[cut:].tolist(),
                    noise[cut:].tolist())  # fmt: skip
    pv, op, mv = (np.array(a + b, dtype=np.float64) for a, b in zip(first, rest, strict=True))
    return loop_record(cfg, rng, t, sp, pv, op, mv)


LoopInputs = tuple[np.random.Generator, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]
"""What a run is driven by: the run's generator (its later draws make the stem sensor's noise),
time (s), set point, load, output disturbance and measurement noise, one value per sample."""


def loop_inputs(cfg: LoopConfig) -> LoopInputs:
    """The signals a run of ``cfg`` is driven by, warm-up included, drawn from ``cfg.seed``."""
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
    starts = np.array([t_step + cfg.warmup_samples * ts for t_step, _ in cfg.sp_steps])
    if starts.size and np.all(starts[1:] >= starts[:-1]):
        # moves in time order (a ramp or a cascade master's output: hundreds of them): each
        # sample takes the last move reached, as the assignments below leave it
        reached = np.searchsorted(starts, t, side="right")
        levels = np.array([value for _, value in cfg.sp_steps], dtype=np.float64)
        sp = np.where(reached > 0, levels[np.maximum(reached - 1, 0)], sp)
    else:
        for t_step, value in cfg.sp_steps:
            sp[t >= t_step + cfg.warmup_samples * ts] = value
    return rng, t, sp, load, out_d, noise


def loop_record(
    cfg: LoopConfig,
    rng: np.random.Generator,
    t: FloatArray,
    sp: FloatArray,
    pv: FloatArray,
    op: FloatArray,
    mv: FloatArray,
) -> LoopRecord:
    """The record of a run (``loop_inputs``' ``rng``, ``t`` and ``sp``, the run's PV, OP and
    MV): the samples after warm-up, PV and OP as the historian keeps them, MV with its
    sensor's noise."""
    n_total = t.size
    if cfg.mv_noise_std:
        mv = mv + rng.normal(0.0, cfg.mv_noise_std, n_total)
    keep = slice(cfg.warmup_samples, n_total)
    return LoopRecord(
        t=t[keep] - t[cfg.warmup_samples],
        sp=sp[keep],
        pv=recorded_pv(pv[keep], cfg.pv_quantum, cfg.pv_compression, cfg.interpolated),
        op=recorded_pv(op[keep], 0.0, cfg.op_compression, cfg.interpolated),
        mv=mv[keep],
    )
