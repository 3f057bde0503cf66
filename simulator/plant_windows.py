"""Labelled windows as running plants give them (issue 25): set-point steps, output limits
anywhere, disturbances at any period, quantised PV, several noise levels, in every class.

The case matrix of ``cases.py`` holds each loop at a constant set point with its output free
between 0 and 100 %. Real two-hour windows hold zero to four set-point moves, DCS output limits
set anywhere between 50 and 95 %, loads that push the output onto them, and disturbances whose
period may be close to the loop's own. Every case here draws those conditions independently of
its class, so a weakness shows per family (``family`` of each case).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace

import numpy as np

from plantcheck.core.vocabulary import CAUSES
from plantcheck.simulator.cases import (
    PROCESSES,
    VISIBLE_SLIP_NOISE,
    Case,
    ProcessSetup,
    _random_loads,
    process_setup,
    slip_on_pv,
)
from plantcheck.simulator.loop import Disturbance, LoopConfig, Process

CLASSES = CAUSES[:6]
"""The causes every family holds: the contract's first six (ok, stiction, aggressive and
sluggish tuning, external disturbance, saturation), the ones a loop can be built to show."""

LENGTHS = (2000, 3600, 6000)
"""Window lengths in samples (the independent simulator of issue 25 used 2,000-6,000)."""


@dataclass(frozen=True)
class PlantWindowCase:
    """A labelled window and the conditions it was drawn with."""

    case: Case
    sp_steps: int
    """Set-point steps in the window (0-4)."""
    op_limit: float | None
    """The output limit (%) below 100 %, or None when the output is free to 100 %."""
    recording: str
    """``continuous`` or ``quantised`` PV."""
    noise: float
    """PV noise σ, % of span."""


def steady_op(proc: Process, sp: float, load: float = 0.0, u0: float = 50.0) -> float:
    """Controller output (%) that holds PV at ``sp`` against a constant ``load`` (% at the
    process input); the simulated process is in deviations around OP ``u0`` at PV 50 %."""
    if proc.kind == "integrating":
        return u0 - load
    return u0 + (sp - 50.0) / proc.K - load


def generate_plant_window_cases(
    seed: int = 1,
    per_cell: int = 2,
    processes: Mapping[str, tuple[str, Process]] | None = None,
) -> Iterator[PlantWindowCase]:
    """Every class × process × noise level (σ 0.05, 0.2, 0.5 %) × ``per_cell``, on the
    processes of ``cases.PROCESSES`` or of ``processes`` (e.g. one of
    ``cases.OTHER_PROCESS_SETS``: tables the chain was not developed on).

    Each window draws, whatever its class: a length from ``LENGTHS``; 0-4 set-point steps of
    2-5 % around 50 % at random times; an output limit (half the windows) 8-25 % above the
    steady output, so that set-point moves and loads touch it briefly; a quantised PV (a third
    of the windows, one to three noise σ a step). The classes:

    - ``ok``: SIMC PI (Skogestad 2003), random load steps;
    - ``stiction``: a Kano or He valve, S 1-8 %, J/S 0.2-1, both raised where the slip would
      move the PV by less than 4 × its noise and recording step (the short-window family's
      rule: a slip hidden in the noise is a valve the standard chain cannot see);
    - ``aggressive_tuning``: gain 0.8-0.95 of the ultimate gain, coloured load;
    - ``sluggish_tuning``: gain × 0.2, integral time × 5 (methods §9.1), load steps;
    - ``external_disturbance``: a sinusoidal load with a period of 0.5-20 × the loop's
      ultimate period (issue 25 item 4), at most an eighth of the window;
    - ``saturation``: the output limit at 50-95 % below what the loop needs after a load step
      early in the window (10-30 %), so that the output rests at its limit with PV off set
      point for most of it.
    """
    rng = np.random.default_rng(seed)
    table = processes or PROCESSES
    for pname in table:
        su = process_setup(pname, table)
        for noise in (0.05, 0.2, 0.5):
            for rep in range(per_cell):
                for cause in CLASSES:
                    yield _draw(rng, pname, su, noise, rep, cause)


def _draw(
    rng: np.random.Generator,
    pname: str,
    su: ProcessSetup,
    noise: float,
    rep: int,
    cause: str,
) -> PlantWindowCase:
    proc, ts = su.process, su.ts
    n = int(rng.choice(LENGTHS))
    dur = n * ts
    n_steps = int(rng.integers(0, 5))
    times = np.sort(rng.uniform(0.1, 0.9, n_steps)) * dur
    levels = 50.0 + rng.choice([-1.0, 1.0], n_steps) * rng.uniform(2.0, 5.0, n_steps)
    sp_steps = tuple((float(t), float(v)) for t, v in zip(times, levels, strict=True))
    quantised = rng.uniform() < 1.0 / 3.0
    quantum = float(rng.uniform(1.0, 3.0)) * noise if quantised else 0.0
    pi = su.pi
    limit: float | None = None
    if rng.uniform() < 0.5:
        limit = min(95.0, max(50.0, steady_op(proc, 50.0) + float(rng.uniform(8.0, 25.0))))
    loads: tuple[Disturbance, ...] = (_random_loads(rng, dur, 40 * su.tu, 1.0),)
    extra = ""
    valve = "linear"
    S = J = 0.0
    if cause == "stiction":
        S = float(rng.choice([1.0, 2.0, 4.0, 8.0]))
        J = S * float(rng.choice([0.2, 0.5, 1.0]))
        # a slip the PV shows, as in the short-window family
        grow = VISIBLE_SLIP_NOISE * max(noise, quantum) / slip_on_pv(proc, J, ts)
        if grow > 1.0:
            S, J = round(S * grow, 1), round(J * grow, 1)
        valve = "kano" if rng.uniform() < 0.5 else "he"
        loads = (_random_loads(rng, dur, 40 * su.tu, 0.3 * S),)
        extra = f"-{valve}-S{S:g}-J{J:g}"
    elif cause == "aggressive_tuning":
        frac = float(rng.uniform(0.8, 0.95))
        pi = replace(pi, Kc=frac * su.ku)
        loads = (Disturbance(filtered_noise_std=1.0, filtered_noise_tau_s=su.tu),)
        extra = f"-{frac:.2f}Ku"
    elif cause == "sluggish_tuning":
        pi = replace(pi, Kc=0.2 * pi.Kc, Ti_s=5 * pi.Ti_s)
        loads = (_random_loads(rng, dur, 30 * su.tu * 5, 3.0),)
    elif cause == "external_disturbance":
        mult = float(np.exp(rng.uniform(np.log(0.5), np.log(20.0))))
        period = min(mult * su.tu, dur / 8)
        amp = float(rng.uniform(2.0, 6.0))
        loads = (Disturbance(where="load", sine_amplitude=amp, sine_period_s=period),)
        extra = f"-T{period:.0f}s-{period / su.tu:.1f}Tu"
    elif cause == "saturation":
        limit = float(rng.uniform(50.0, 95.0))
        # a load step early on asks for 3-10 % more output than the limit allows
        need = limit + float(rng.uniform(3.0, 10.0))
        load = steady_op(proc, 50.0) - need
        at = float(rng.uniform(0.1, 0.3)) * dur
        loads = (Disturbance(where="load", steps=((at, load),)),)
        sp_steps = tuple((t, v) for t, v in sp_steps if t < at)
        n_steps = len(sp_steps)
        extra = f"-limit{limit:.0f}"
    if limit is not None:
        pi = replace(pi, op_max=limit)
    recording = "quantised" if quantised else "continuous"
    tag = (
        f"{pname}-n{n}-steps{n_steps}-"
        f"{'limit' + format(limit, '.0f') if limit is not None else 'free'}-"
        f"{recording}-noise{noise}-r{rep}"
    )
    cfg = LoopConfig(
        process=proc,
        controller=pi,
        valve=valve,  # type: ignore[arg-type]
        S=S,
        J=J,
        disturbances=loads,
        noise_std=noise,
        sp_steps=sp_steps,
        sample_time_s=ts,
        n_samples=n,
        warmup_samples=int(20 * su.tu / ts) + 200,
        pv_quantum=quantum,
        seed=int(rng.integers(1 << 30)),
    )
    return PlantWindowCase(
        Case(f"{cause}{extra}-{tag}", cause, su.loop_type, cfg), n_steps, limit, recording, noise
    )
