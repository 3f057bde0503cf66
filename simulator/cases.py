"""Labelled closed-loop cases for testing and calibrating the diagnosis (methods.md §9.1).

Each case is a ``LoopConfig`` plus its true cause. Controllers are tuned by SIMC
(Skogestad 2003, τ_c = θ) and modified per class: aggressive = gain at 0.8–0.95 of the
ultimate gain; sluggish = Kc × 0.2 and Ti × 5 (methods §9.1); sticky valves use the Kano
or He model; external disturbances are sinusoids with a period 5–50× the process time
constant (or several closed-loop time scales for integrating processes).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from plantcheck.simulator.actuator import ActuatorSpec
from plantcheck.simulator.loop import (
    Disturbance,
    FloatArray,
    LoopConfig,
    PIController,
    Process,
    simulate_loop,
)

PROCESSES: dict[str, tuple[str, Process]] = {
    "flow": ("flow", Process("fopdt", K=1.0, tau_s=2.0, theta_s=1.0)),
    "pressure": ("pressure", Process("fopdt", K=1.5, tau_s=8.0, theta_s=2.0)),
    "temperature": ("temperature", Process("fopdt", K=2.0, tau_s=20.0, theta_s=5.0)),
    "temperature2": ("temperature", Process("fopdt", K=1.0, tau_s=30.0, theta_s=10.0, tau2_s=10.0)),
    "composition": ("composition", Process("fopdt", K=1.0, tau_s=150.0, theta_s=40.0)),
    "level": ("level", Process("integrating", K=0.1, theta_s=2.0)),
}


def _process_table(
    flow: Process,
    pressure: Process,
    temperature: Process,
    temperature2: Process,
    composition: Process,
    level: Process,
) -> dict[str, tuple[str, Process]]:
    """A process table with the names and loop types of ``PROCESSES``."""
    return {
        "flow": ("flow", flow),
        "pressure": ("pressure", pressure),
        "temperature": ("temperature", temperature),
        "temperature2": ("temperature", temperature2),
        "composition": ("composition", composition),
        "level": ("level", level),
    }


OTHER_PROCESS_SETS: dict[str, dict[str, tuple[str, Process]]] = {
    "long-lags": _process_table(
        flow=Process("fopdt", K=0.6, tau_s=4.0, theta_s=0.6),
        pressure=Process("fopdt", K=0.8, tau_s=25.0, theta_s=3.0),
        temperature=Process("fopdt", K=1.5, tau_s=60.0, theta_s=12.0),
        temperature2=Process("fopdt", K=2.0, tau_s=80.0, theta_s=6.0, tau2_s=25.0),
        composition=Process("fopdt", K=1.8, tau_s=400.0, theta_s=90.0),
        level=Process("integrating", K=0.04, theta_s=5.0),
    ),
    "short-dead-times": _process_table(
        flow=Process("fopdt", K=1.5, tau_s=1.5, theta_s=1.5),
        pressure=Process("fopdt", K=2.5, tau_s=5.0, theta_s=1.0, tau2_s=2.0),
        temperature=Process("fopdt", K=0.7, tau_s=120.0, theta_s=8.0),
        temperature2=Process("fopdt", K=1.2, tau_s=40.0, theta_s=20.0, tau2_s=15.0),
        composition=Process("fopdt", K=0.5, tau_s=90.0, theta_s=60.0),
        level=Process("integrating", K=0.2, theta_s=1.0),
    ),
}
"""Process tables the chain was not developed on, with the names of ``PROCESSES``: other
gains, lags and dead times, so that a benchmark can show what the chain owes to the one table
it was tuned on. ``long-lags``: slower lags and longer dead times; ``short-dead-times``: dead
times of one to five samples, where a healthy loop's own frequency lies a few samples long."""


VISIBLE_SLIP_NOISE = 4.0
"""A sticky case's slip moves the PV by at least this many × its noise and recording step: the
events an engineer sees on the trend (a smaller slip is a valve the standard chain cannot see)."""


def slip_on_pv(proc: Process, J: float, ts: float) -> float:
    """PV move (PV units) a valve slip of ``J`` % causes: through the gain, or for a level
    through its integration over 20 samples of ``ts`` s."""
    return proc.K * J * (20.0 * ts if proc.kind == "integrating" else 1.0)


def simc_pi(p: Process) -> PIController:
    """SIMC PI tuning with τ_c = θ (Skogestad 2003); θ includes half the second lag."""
    return simc_pi_tc(p, 1.0)


def effective_dead_time(p: Process) -> float:
    """SIMC's effective dead time (s): θ, half the second lag, and an inverse response's
    right-half-plane zero (Skogestad 2003, the half rule)."""
    return max(p.theta_s + p.tau2_s / 2.0 + max(0.0, -p.zero_s), 0.5)


def simc_pi_tc(p: Process, tc_over_theta: float) -> PIController:
    """SIMC PI tuning (Skogestad 2003) with the closed-loop time constant τ_c set to
    ``tc_over_theta`` × the effective dead time: 1 is SIMC's tight-but-robust choice, larger
    is slower and more robust."""
    theta = effective_dead_time(p)
    tc = tc_over_theta * theta
    if p.kind == "integrating":
        kc = 1.0 / (p.K * (tc + theta))
        return PIController(Kc=kc, Ti_s=4.0 * (tc + theta))
    kc = p.tau_s / (p.K * (tc + theta))
    return PIController(Kc=kc, Ti_s=min(p.tau_s, 4.0 * (tc + theta)))


def _loop_gain(p: Process, ti: float, w: float, ts: float) -> complex:
    """L(jω)/Kc for a PI controller and the process, with a half-sample ZOH delay."""
    s = 1j * w
    c = 1.0 + 1.0 / (ti * s)
    delay = np.exp(-s * (p.theta_s + ts / 2.0))
    if p.kind == "integrating":
        g = p.K / s
    else:
        g = p.K / (p.tau_s * s + 1.0)
        if p.tau2_s > 0:
            g = g * (1.0 + p.zero_s * s) / (p.tau2_s * s + 1.0)
    return complex(c * g * delay)


def _c_prod(ar: Any, ai: Any, br: Any, bi: Any) -> tuple[Any, Any]:
    """CPython's complex product (``_Py_c_prod``) on real and imaginary parts, elementwise."""
    return ar * br - ai * bi, ar * bi + ai * br


def _c_quot(ar: Any, ai: Any, br: NDArray[np.float64], bi: NDArray[np.float64]) -> tuple[Any, Any]:
    """CPython 3.11's complex quotient (``_Py_c_quot``, Smith's method: the larger part of
    the divisor divides the smaller), elementwise. numpy's own complex division rounds
    differently in the last bit."""
    first = np.abs(br) >= np.abs(bi)
    with np.errstate(all="ignore"):  # the branch not taken may divide by zero
        r1 = bi / br
        d1 = br + bi * r1
        r2 = br / bi
        d2 = br * r2 + bi
        re = np.where(first, (ar + ai * r1) / d1, (ar * r2 + ai) / d2)
        im = np.where(first, (ai - ar * r1) / d1, (ai * r2 - ar) / d2)
    return re, im


def _loop_gains(
    p: Process, ti: float, ws: NDArray[np.float64], ts: float
) -> NDArray[np.complex128]:
    """``_loop_gain`` at every frequency of ``ws``, the same values bit for bit: its Python
    complex arithmetic spelled out on real arrays (a float operand is a complex with a 0.0
    imaginary part, as CPython converts it), its ``np.exp`` the same, and its last product
    numpy's complex scalar product. Ten times faster than 2,000 calls, which were a fifth of a
    corpus window's draw."""
    zero = np.zeros_like(ws)
    sr, si = _c_prod(0.0, 1.0, ws, zero)  # s = 1j·ω
    tr, ti_s = _c_prod(ti, 0.0, sr, si)
    qr, qi = _c_quot(1.0, 0.0, tr, ti_s)
    cr, ci = 1.0 + qr, 0.0 + qi
    er, ei = _c_prod(-sr, -si, p.theta_s + ts / 2.0, 0.0)
    arg = np.empty(ws.size, dtype=np.complex128)
    arg.real, arg.imag = er, ei
    delay = np.exp(arg)
    if p.kind == "integrating":
        gr, gi = _c_quot(p.K, 0.0, sr, si)
    else:
        lr, li = _c_prod(p.tau_s, 0.0, sr, si)
        gr, gi = _c_quot(p.K, 0.0, lr + 1.0, li + 0.0)
        if p.tau2_s > 0:
            zr, zi = _c_prod(p.zero_s, 0.0, sr, si)
            gr, gi = _c_prod(gr, gi, 1.0 + zr, 0.0 + zi)
            lr, li = _c_prod(p.tau2_s, 0.0, sr, si)
            gr, gi = _c_quot(gr, gi, lr + 1.0, li + 0.0)
    pr, pi_ = _c_prod(cr, ci, gr, gi)
    out = np.empty(ws.size, dtype=np.complex128)
    out.real, out.imag = _c_prod(pr, pi_, delay.real, delay.imag)
    return out


def ultimate_gain(p: Process, ti: float, ts: float) -> tuple[float, float]:
    """Ultimate gain Ku and period Tu (s) of the PI loop with integral time ``ti``."""
    ws = np.logspace(-4, math.log10(math.pi / ts), 2000)
    ph = np.unwrap(np.angle(_loop_gains(p, ti, ws, ts)))
    idx = np.flatnonzero(ph < -math.pi)
    i = int(idx[0])
    wu = float(brentq(lambda w: float(np.interp(w, ws, ph)) + math.pi, ws[i - 1], ws[i]))
    ku = 1.0 / abs(_loop_gain(p, ti, wu, ts))
    return ku, 2.0 * math.pi / wu


@dataclass(frozen=True)
class ProcessSetup:
    """A named process with its sample time (s), SIMC PI tuning, ultimate gain and period (s)."""

    loop_type: str
    process: Process
    ts: float
    pi: PIController
    ku: float
    tu: float


def process_setup(
    pname: str, processes: Mapping[str, tuple[str, Process]] | None = None
) -> ProcessSetup:
    """Sample time from the process' slowest time scale (0.2 s … 10 s), SIMC tuning, Ku, Tu,
    for the process ``pname`` of ``processes`` (default ``PROCESSES``)."""
    loop_type, proc = (processes or PROCESSES)[pname]
    slow = proc.tau_s + proc.theta_s + proc.tau2_s if proc.kind == "fopdt" else 20.0
    ts = float(np.clip(round(slow / 20.0, 1), 0.2, 10.0))  # 0.2 s (flow) … 9.5 s (analyser)
    pi = simc_pi(proc)
    ku, tu = ultimate_gain(proc, pi.Ti_s, ts)
    return ProcessSetup(loop_type, proc, ts, pi, ku, tu)


@dataclass(frozen=True)
class Case:
    """A labelled simulated loop."""

    name: str
    cause: str
    loop_type: str
    config: LoopConfig


def _random_loads(
    rng: np.random.Generator, duration_s: float, every_s: float, size: float
) -> Disturbance:
    n = max(2, int(duration_s / every_s))
    times = np.sort(rng.uniform(0, duration_s, n))
    sizes = rng.normal(0, size, n)
    return Disturbance(where="load", steps=tuple(zip(times.tolist(), sizes.tolist(), strict=True)))


def generate_cases(
    seed: int = 1, per_cell: int = 1, lengths: tuple[int, ...] = (3000,)
) -> Iterator[Case]:
    """Yield the labelled case matrix: every cause × process × noise level × length.

    Sample times scale with the process (0.2 s for flow up to several seconds for slow loops).
    """
    rng = np.random.default_rng(seed)
    noise_levels = (0.05, 0.2, 0.5)
    for pname in PROCESSES:
        su = process_setup(pname)
        loop_type, proc, ts, base_pi, ku, tu = su.loop_type, su.process, su.ts, su.pi, su.ku, su.tu
        for n in lengths:
            dur = n * ts
            for noise in noise_levels:
                for rep in range(per_cell):
                    s = int(rng.integers(1 << 30))
                    tag = f"{pname}-n{n}-noise{noise}-r{rep}"
                    common: dict[str, object] = dict(
                        process=proc,
                        sample_time_s=ts,
                        n_samples=n,
                        warmup_samples=int(20 * tu / ts) + 200,
                        noise_std=noise,
                        seed=s,
                    )
                    load_std = 1.0
                    yield Case(
                        f"ok-{tag}",
                        "ok",
                        loop_type,
                        LoopConfig(
                            controller=base_pi,
                            disturbances=(_random_loads(rng, dur, 40 * tu, load_std),),
                            **common,  # type: ignore[arg-type]
                        ),
                    )
                    S = float(rng.choice([1.0, 2.0, 4.0, 8.0]))
                    J = S * float(rng.choice([0.2, 0.5, 1.0]))
                    valve = "kano" if rng.uniform() < 0.5 else "he"
                    yield Case(
                        f"stiction-{valve}-S{S:g}-J{J:g}-{tag}",
                        "stiction",
                        loop_type,
                        LoopConfig(
                            controller=base_pi,
                            valve=valve,  # type: ignore[arg-type]
                            S=S,
                            J=J,
                            disturbances=(_random_loads(rng, dur, 40 * tu, 0.3 * S),),
                            **common,  # type: ignore[arg-type]
                        ),
                    )
                    frac = float(rng.uniform(0.8, 0.95))
                    yield Case(
                        f"aggressive-{frac:.2f}Ku-{tag}",
                        "aggressive_tuning",
                        loop_type,
                        LoopConfig(
                            controller=replace(base_pi, Kc=frac * ku),
                            disturbances=(
                                Disturbance(filtered_noise_std=1.0, filtered_noise_tau_s=tu),
                            ),
                            **common,  # type: ignore[arg-type]
                        ),
                    )
                    yield Case(
                        f"sluggish-{tag}",
                        "sluggish_tuning",
                        loop_type,
                        LoopConfig(
                            controller=replace(base_pi, Kc=0.2 * base_pi.Kc, Ti_s=5 * base_pi.Ti_s),
                            disturbances=(_random_loads(rng, dur, 30 * tu * 5, 3 * load_std),),
                            **common,  # type: ignore[arg-type]
                        ),
                    )
                    mult = float(rng.uniform(5, 50))
                    period = mult * (proc.tau_s if proc.kind == "fopdt" else tu)
                    period = min(period, dur / 8)
                    yield Case(
                        f"disturbance-T{period:.0f}s-{tag}",
                        "external_disturbance",
                        loop_type,
                        LoopConfig(
                            controller=base_pi,
                            disturbances=(
                                Disturbance(
                                    where="load",
                                    sine_amplitude=float(rng.uniform(2.0, 6.0)),
                                    sine_period_s=period,
                                ),
                            ),
                            **common,  # type: ignore[arg-type]
                        ),
                    )


SHORT_WINDOW_SAMPLES = 720
"""Two hours at 10 s: the window real plants give (refinery-stiction-dev)."""


def _short_window_loop(rng: np.random.Generator) -> tuple[str, Process]:
    """A slow loop as plants have them: self-regulating with τ 40–300 s (an analyser,
    pressure, temperature) or a level with its integrating dynamics.

    Not a flow loop: a flow follows its valve within seconds (Kano et al. 2004 and Yamashita
    2006 read the flow as the valve position; the chain bounds a flow loop's dynamics so), so
    a "flow" of τ 300 s is no plant's. Until 2026-11-25 the first kind drawn here was called
    flow; the draws are the same, only that name changed."""
    if rng.uniform() < 0.2:
        return "level", Process("integrating", K=float(rng.uniform(0.002, 0.01)), theta_s=10.0)
    tau = float(rng.uniform(40.0, 300.0))
    theta = float(rng.uniform(0.05, 0.3)) * tau
    kind = str(rng.choice(["composition", "pressure", "temperature"]))
    return kind, Process("fopdt", K=float(rng.uniform(0.5, 2.0)), tau_s=tau, theta_s=theta)


def valve_breakaways(mv: FloatArray, min_jump: float, min_stuck: int = 3) -> int:
    """Stick-slip events of a simulated valve: moves of at least ``min_jump`` (% of travel)
    out of a rest of at least ``min_stuck`` samples (the true count, from the stem position)."""
    moved = np.abs(np.diff(mv)) > 1e-9
    count = 0
    rest = 0
    for k in range(moved.size):
        if moved[k]:
            if rest >= min_stuck and abs(mv[k + 1] - mv[k]) >= min_jump:
                count += 1
            rest = 0
        else:
            rest += 1
    return count


def _fast_flow_loop(rng: np.random.Generator) -> tuple[str, Process]:
    """A flow loop as the refinery records show it: the flow follows the valve within seconds
    (τ 2–8 s, dead time 0–4 s), recorded at 10 s."""
    tau = float(rng.uniform(2.0, 8.0))
    proc = Process(
        "fopdt", K=float(rng.uniform(0.5, 2.0)), tau_s=tau, theta_s=float(rng.uniform(0, 4))
    )
    return "flow", proc


def _fast_flow_pi(proc: Process, rng: np.random.Generator) -> PIController:
    """A flow controller as a 10 s record shows it: integral action that moves OP by hundredths
    of a percent per sample (refinery-stiction-dev: OP ramps of 1–3 % over minutes), a small
    proportional gain."""
    return PIController(
        Kc=float(rng.uniform(0.1, 0.4)) / proc.K, Ti_s=float(rng.uniform(100.0, 600.0))
    )


def _short_window_case(
    rng: np.random.Generator,
    noise: float,
    recording: str,
    fast_flow: bool,
    max_tries: int,
) -> tuple[str, int, int, LoopConfig, dict[str, object]]:
    """One sticky window within the family's spec and what its healthy twin shares with it:
    (loop type, set-point steps, stick-slip events, sticky config, the twin's settings)."""
    ts = 10.0
    n = SHORT_WINDOW_SAMPLES
    dur = n * ts
    for _ in range(max_tries):
        if fast_flow:
            loop_type, proc = _fast_flow_loop(rng)
            pi = _fast_flow_pi(proc, rng)
        else:
            loop_type, proc = _short_window_loop(rng)
            pi = simc_pi(proc)
            pi = replace(
                pi,
                Kc=pi.Kc / float(rng.uniform(1.0, 3.0)),
                Ti_s=pi.Ti_s * float(rng.uniform(2.0, 8.0)),
            )
        n_steps = int(rng.integers(0, 4))
        times = np.sort(rng.uniform(0.1, 0.9, n_steps)) * dur
        sizes = rng.choice([-1.0, 1.0], n_steps) * rng.uniform(1.0, 5.0, n_steps)
        sp_steps = tuple(
            (float(t), 50.0 + float(v)) for t, v in zip(times, np.cumsum(sizes), strict=True)
        )
        loads = (
            Disturbance(random_walk_std=float(rng.uniform(0.002, 0.01))),
            _random_loads(rng, dur, dur / 2.0, 1.0),
        )
        quantum = float(rng.uniform(1.0, 3.0)) * noise if recording == "quantised" else 0.0
        compression = float(rng.uniform(1.0, 3.0)) * noise if recording == "compressed" else 0.0
        S = float(rng.choice([1.0, 2.0, 3.0, 4.0, 6.0]))
        J = round(S * float(rng.uniform(0.5, 1.0)), 2)
        valve = "kano" if rng.uniform() < 0.5 else "he"
        common: dict[str, object] = dict(
            process=proc,
            controller=pi,
            sample_time_s=ts,
            n_samples=n,
            warmup_samples=200,
            noise_std=noise,
            sp_steps=sp_steps,
            disturbances=loads,
            pv_quantum=quantum,
            pv_compression=compression,
            seed=int(rng.integers(1 << 30)),
        )
        sticky = LoopConfig(valve=valve, S=S, J=J, **common)  # type: ignore[arg-type]
        # a slip an engineer can see on the trend: the PV move it causes (over 20 samples for a
        # level) stands 4 × above the noise and the recording step
        visible = slip_on_pv(proc, J, ts) >= VISIBLE_SLIP_NOISE * max(noise, quantum, compression)
        events = valve_breakaways(simulate_loop(sticky).mv, 0.5 * J) if visible else 0
        if 1 <= events <= 3:
            return loop_type, n_steps, events, sticky, common
    raise RuntimeError(
        f"no sticky case with 1-3 visible events in {max_tries} draws at noise {noise} "
        f"({recording}); raise max_tries"
    )


def generate_short_window_cases(
    seed: int = 1, per_cell: int = 4, max_tries: int = 300
) -> Iterator[Case]:
    """Two-hour windows at 10 s of slow loops and of flows, sticky and healthy, as real plants
    give them.

    The family issue 24 asks for: slow processes (τ 40–300 s, or a level), SIMC PI tuning
    detuned (gain / 1–3, integral time × 2–8: plants run conservative loops, and a sticky valve
    under a slow integral shows few events rather than a limit cycle), zero to three set-point
    steps, slowly drifting loads with an occasional step, PV noise σ 0.05–0.5 % of span and a
    recorded PV that is continuous, quantised or historian-compressed. A sticky case has a Kano
    or He valve with S 1–6 % and J/S 0.5–1 (real sticky valves slip by most of their stickband)
    and shows one to three stick-slip events in the window, counted on the simulated stem
    position, each moving the PV by at least 4 × its noise and recording step (the events an
    engineer sees on the trend); cases that miss either are drawn again, up to ``max_tries``
    times (a family that cannot be drawn raises rather than yield cases outside its spec).
    Each sticky case has a healthy twin: the same process, tuning, noise, set-point steps,
    loads and recording, with a linear valve.

    As many flow loops of the refinery records' kind follow, from a random stream of their own
    (so the slow loops are the same draws as before they were added): τ 2–8 s, a controller
    whose integral moves OP by hundredths of a percent per 10 s sample (``_fast_flow_pi``).
    """
    kinds = ((np.random.default_rng(seed), False), (np.random.default_rng([seed, 2]), True))
    for draw, fast in kinds:
        for noise in (0.05, 0.2, 0.5):
            for recording in ("continuous", "quantised", "compressed"):
                for rep in range(per_cell):
                    loop_type, n_steps, events, sticky, common = _short_window_case(
                        draw, noise, recording, fast, max_tries
                    )
                    valve, S, J = sticky.valve, sticky.S, sticky.J
                    tag = f"{loop_type}-steps{n_steps}-noise{noise}-{recording}-r{rep}"
                    yield Case(f"stiction-{valve}-S{S:g}-J{J:g}-events{events}-{tag}", "stiction",
                               loop_type, sticky)  # fmt: skip
                    yield Case(f"ok-{tag}", "ok", loop_type, LoopConfig(**common))  # type: ignore[arg-type]


def sticky_flow_config(n_samples: int = 3600, seed: int = 3) -> LoopConfig:
    """The reference sticky flow loop of the benchmarks: Kano valve S = 3 %, J = 1 %, Ts = 1 s."""
    return LoopConfig(
        process=Process(K=1.0, tau_s=2.0, theta_s=1.0),
        controller=PIController(Kc=0.4, Ti_s=2.0),
        valve="kano",
        S=3.0,
        J=1.0,
        noise_std=0.1,
        disturbances=(Disturbance(random_walk_std=0.02),),
        n_samples=n_samples,
        warmup_samples=300,
        seed=seed,
    )


@dataclass(frozen=True)
class ActuatorCase:
    """A labelled loop with a measured stem position: true loop cause and true valve state."""

    name: str
    cause: str
    valve_state: str
    loop_type: str
    config: LoopConfig
    S: float | None = None
    J: float | None = None


ACTUATOR_PROCESSES = ("flow", "pressure", "temperature", "level")


def _actuator_case(
    name: str,
    cause: str,
    state: str,
    *,
    loop_type: str,
    tag: str,
    common: dict[str, object],
    loads: tuple[Disturbance, ...],
    **kw: object,
) -> ActuatorCase:
    cfg_kw = {**common, "disturbances": loads, **kw}
    friction = state in ("stiction", "deadband_backlash")
    return ActuatorCase(
        f"{name}-{tag}",
        cause,
        state,
        loop_type,
        LoopConfig(**cfg_kw),  # type: ignore[arg-type]
        kw.get("S") if friction else None,  # type: ignore[arg-type]
        kw.get("J") if friction else None,  # type: ignore[arg-type]
    )


def generate_actuator_cases(seed: int = 1, per_cell: int = 2) -> Iterator[ActuatorCase]:
    """Cases for the advanced chain: every actuator class and healthy valves in oscillating
    loops (aggressive tuning, external disturbance), over loop types, noise levels and sizes."""
    rng = np.random.default_rng(seed)
    for pname in ACTUATOR_PROCESSES:
        su = process_setup(pname)
        loop_type, proc, ts, base_pi, ku, tu = su.loop_type, su.process, su.ts, su.pi, su.ku, su.tu
        n = 3600
        dur = n * ts
        for rep in range(per_cell):
            # noise as seen on OP (Kc·σ_PV): 0.05–0.3 % of travel whatever the loop's gain
            op_noise = float(rng.choice([0.05, 0.15, 0.3]))
            noise = op_noise / abs(base_pi.Kc)
            common: dict[str, object] = dict(
                process=proc,
                sample_time_s=ts,
                n_samples=n,
                warmup_samples=int(20 * tu / ts) + 200,
                noise_std=noise,
                mv_noise_std=0.03,
                seed=int(rng.integers(1 << 30)),
                controller=base_pi,
            )
            loads = (_random_loads(rng, dur, 10 * tu, 2.0),)
            tag = f"{pname}-opnoise{op_noise}-r{rep}"

            case = partial(_actuator_case, loop_type=loop_type, tag=tag, common=common, loads=loads)
            yield case("valve-ok", "ok", "ok", actuator=ActuatorSpec())
            S = float(rng.choice([1.0, 2.0, 4.0]))
            yield case(
                f"stiction-S{S:g}", "stiction", "stiction",
                valve="kano", S=S, J=S * float(rng.choice([0.5, 1.0])), actuator=ActuatorSpec(),
            )  # fmt: skip
            yield case(
                f"deadband-S{S:g}", "deadband_backlash", "deadband_backlash",
                valve="kano", S=S, J=0.0, actuator=ActuatorSpec(),
            )  # fmt: skip
            bias = float(rng.choice([-1, 1])) * float(rng.uniform(2.0, 5.0))
            gain = float(rng.choice([1.0, 0.85, 1.15]))
            yield case(
                "calibration", "positioner_fault", "positioner_fault",
                actuator=ActuatorSpec("calibration", bias=bias, gain=gain),
            )  # fmt: skip
            yield case(
                "hunting", "positioner_tuning", "positioner_tuning",
                actuator=ActuatorSpec(
                    "hunting",
                    hunting_amplitude=float(rng.uniform(0.5, 2.0)),
                    hunting_period_s=float(rng.uniform(3.0, 10.0)) * max(ts, 0.5),
                ),
            )  # fmt: skip
            yield case(
                "air-leakage", "air_leakage", "air_leakage",
                actuator=ActuatorSpec("air_leakage", leak_rate=float(rng.uniform(2.0, 6.0)) / dur),
            )  # fmt: skip
            yield case(
                "undersized", "actuator_undersized", "actuator_undersized",
                disturbances=(_random_loads(rng, dur, 5 * tu, 8.0),),
                actuator=ActuatorSpec("rate_limit", rate=float(rng.uniform(0.05, 0.2))),
            )  # fmt: skip
            frac = float(rng.uniform(0.8, 0.95))
            yield case(
                "aggressive-healthy-valve", "aggressive_tuning", "ok",
                controller=replace(base_pi, Kc=frac * ku),
                disturbances=(Disturbance(filtered_noise_std=1.0, filtered_noise_tau_s=tu),),
                actuator=ActuatorSpec(),
            )  # fmt: skip
            period = min(
                float(rng.uniform(5, 50)) * (proc.tau_s if proc.kind == "fopdt" else tu), dur / 8
            )
            yield case(
                "disturbance-healthy-valve", "external_disturbance", "ok",
                disturbances=(
                    Disturbance(sine_amplitude=float(rng.uniform(2.0, 6.0)), sine_period_s=period),
                ),
                actuator=ActuatorSpec(),
            )  # fmt: skip
