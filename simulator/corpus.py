"""A training corpus randomised the way plants differ (issue 46): labelled windows from every
process family, valve model, load, set-point pattern, output limit, recording and operation
(automatic throughout, an unflagged manual stretch, a frozen transmitter), drawn independently
of the class so that the decision learned on it cannot lean on any one of them.

Each window is reproducible from ``(seed, index)`` alone, so a corpus is generated in parallel
and any window can be drawn again. The family each window came from is part of its label
(``CorpusCase.family``): a model can be fitted without one family and tested on it.

Classes are balanced: window ``index`` has class ``CLASSES[index % 6]``. A draw whose fault
the record cannot show (a sticky valve whose cycle hides in the noise, a limit the output never
reaches, a fault whose error is no larger than its twin's: the same loop, loads, noise and set
points without the fault) is drawn again with the next sub-seed, so every label is visible in
its window; the ambiguity that remains (short records, few cycles, noise) is the plant's own.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np

from plantcheck.diagnosis.cause_model import CLAMP_SUPPORT
from plantcheck.diagnosis.signal_tools import hann_power
from plantcheck.simulator.batch_loop import BATCH_SAMPLES, simulate_loops
from plantcheck.simulator.cases import (
    simc_pi_tc,
    ultimate_gain,
)
from plantcheck.simulator.loop import (
    Disturbance,
    LoopConfig,
    LoopRecord,
    PIController,
    Process,
    simulate_loop,
)
from plantcheck.simulator.plant_windows import steady_op

T = TypeVar("T")

CORPUS_VERSION = 11
"""Raised whenever a draw changes: cached evidence of another version is not reused."""

CLASSES: tuple[str, ...] = (
    "ok",
    "stiction",
    "aggressive_tuning",
    "sluggish_tuning",
    "external_disturbance",
    "saturation",
)
"""The causes a simulated loop is built to show (contracts §2's first six)."""

FAMILY_KEYS: tuple[str, ...] = (
    "process", "valve", "load", "sp", "tuning", "limit", "recording", "operation"
)  # fmt: skip
"""The family axes of a window's label; each has the values listed in ``FAMILIES``."""

FAMILIES: dict[str, tuple[str, ...]] = {
    "process": ("fopdt", "sopdt", "integrating", "inverse", "deadtime"),
    "valve": ("linear", "kano", "he", "choudhury", "backlash"),
    "load": ("steps", "ramps", "random_walk", "coloured", "periodic"),
    "sp": ("constant", "steps", "ramps", "cascade"),
    "tuning": ("simc", "detuned", "near_limit", "sluggish"),
    "limit": ("free", "at_100", "anywhere"),
    "recording": ("continuous", "quantised", "compressed", "interpolated"),
    "operation": ("auto", "manual", "frozen"),
}

OPERATION_SHARES = (0.8, 0.1, 0.1)
"""How often a window runs in automatic throughout, holds an unflagged manual stretch, or holds
a frozen transmitter (``FAMILIES["operation"]``; version 11). Operators put loops in manual
for a while and historians rarely keep the mode; transmitters freeze (Thornhill & Horch 2007).
A stretch short enough that the window's cause can still be judged around it: a longer one is
the window checks' to name (``manual_mode``, ``data_quality``), not the decision's."""
MANUAL_SHARE = (0.02, 0.09)
"""Share of a window a manual stretch covers, drawn log-uniformly (version 11)."""
FROZEN_SHARE = (0.01, 0.04)
"""Share of a window a frozen transmitter covers, drawn log-uniformly (version 11)."""

DETUNABLE = frozenset({"stiction", "external_disturbance", "saturation"})
"""Classes whose controller is drawn detuned (gain × 0.03-0.6, integral time × 1-30 of SIMC's,
log-uniform) in half the windows: the fault is the valve, the load or the limit, whatever the
tuning. Plants run loops far slower than the process needs: the refinery-like flows of issue
24's family run an integral time 12-300 times τ; corpus version 7 stopped at 5 times SIMC's,
and no sticky valve it showed had a controller that slow (version 8, 2026-11-30)."""

LIMIT_CYCLE_DUTY = (0.3, 0.7)
"""Share of each period a limit-cycle load is high (square) or rising (triangle), drawn
uniformly (version 10)."""
LIMIT_CYCLE_EDGE_LAG = (0.01, 0.15)
"""The lag a limit-cycle load's edges pass through, as a share of its period, drawn
log-uniformly (version 10)."""

MIN_SAMPLES, MAX_SAMPLES = 150, 12_000
"""Window lengths, drawn log-uniformly: short slow records to a day at a few seconds."""

VISIBLE = 1.6
"""A fault is visible when the control error's σ is at least this many times the noise σ
(its own variance then exceeds the noise's by half again); drawn again otherwise."""

VISIBLY_FAULTY = 1.3
"""A fault shows when its control error's σ is at least this many times its twin's: the same
loop, loads, noise and set points without the fault (its variance 1.7 times; the fault then
makes at least two fifths of it). A slow controller that no load or set-point move tests
looks like a good one (corpus version 4 asked this of sluggish windows alone); a sticky valve
whose cycle the loads swamp, or a periodic load the loop rejects, look like a healthy loop
under its loads: in version 4, 40 % of the stiction and 44 % of the external-disturbance
windows of the check seed raised their error by less than a tenth over their twin's (version
5 asks it of them too). A loop near its stability limit shows in how it rings, not in its
variance (four in five of its draws stay under 1.3 times their well-tuned twin's): it is kept
when its error's power at half to twice the ultimate frequency is at least this squared times
its twin's (version 7; one in six of version 6's were not, and the model read two in five of
those as another cause). Saturation has its own test."""


@dataclass(frozen=True)
class CorpusCase:
    """One labelled window: its configuration, true cause, loop type and family."""

    index: int
    cause: str
    loop_type: str
    config: LoopConfig
    family: dict[str, str]
    ultimate_period_s: float
    twin: LoopConfig | None = None
    """The same loop without its fault (a linear valve, the well-tuned controller, no periodic
    load) for every fault but saturation; else None."""


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _process(rng: np.random.Generator, kind: str, ts: float) -> tuple[Process, str]:
    """A process of the family ``kind`` on the sample time ``ts`` (s), with its loop type."""
    tau = _log_uniform(rng, 3.0, 150.0) * ts
    gain = _log_uniform(rng, 0.3, 3.0)
    theta = _log_uniform(rng, 0.05, 0.8) * tau
    if kind == "integrating":
        # the time the level takes to move by the valve's step, 20-600 samples
        return Process("integrating", K=1.0 / (_log_uniform(rng, 20.0, 600.0) * ts),
                       theta_s=max(ts, _log_uniform(rng, 1.0, 20.0) * ts)), "level"  # fmt: skip
    if kind == "deadtime":
        theta = _log_uniform(rng, 1.2, 5.0) * tau
    proc = Process("fopdt", K=gain, tau_s=tau, theta_s=max(ts, theta))
    if kind in ("sopdt", "inverse"):
        proc = replace(proc, tau2_s=_log_uniform(rng, 0.2, 1.0) * tau)
    if kind == "inverse":
        proc = replace(proc, zero_s=-_log_uniform(rng, 0.3, 1.5) * proc.tau2_s)
    loop_type = str(rng.choice(["flow", "pressure", "temperature", "composition", "other"]))
    return proc, loop_type


def _nuisance_load(
    rng: np.random.Generator, kind: str, dur: float, tu: float, size: float
) -> Disturbance:
    """The load every class carries: steps, ramps (a staircase), a random walk or coloured
    noise, of ``size`` % of travel at the process input."""
    if kind == "steps":
        n = max(1, int(rng.integers(1, 6)))
        times = np.sort(rng.uniform(0.0, dur, n))
        return Disturbance(steps=tuple(zip(times.tolist(), rng.normal(0, size, n).tolist(),
                                           strict=True)))  # fmt: skip
    if kind == "ramps":
        start, length = rng.uniform(0.0, 0.7) * dur, rng.uniform(0.1, 0.4) * dur
        total, k = float(rng.normal(0, 2 * size)), 40
        return Disturbance(steps=tuple((start + length * i / k, total / k) for i in range(k)))
    if kind == "random_walk":
        return Disturbance(random_walk_std=size / math.sqrt(max(dur, 1.0)) * 2.0)
    return Disturbance(filtered_noise_std=size, filtered_noise_tau_s=_log_uniform(rng, 0.3, 5) * tu)


def _periodic_load(
    rng: np.random.Generator, period: float, amp: float, gain: float
) -> tuple[Disturbance, ...]:
    """A disturbance from outside the loop: a sine, or two (a square-ish wave's first
    harmonics), entering at the process input or its output; ``amp`` in PV units, ``gain``
    the PV units a % of travel at the input moves."""
    where = "load" if rng.uniform() < 0.6 else "output"
    size = amp / gain if where == "load" else amp
    first = Disturbance(where=where, sine_amplitude=size, sine_period_s=period)  # type: ignore[arg-type]
    shape = rng.uniform()
    if shape >= 0.4:
        # another loop's limit cycle (version 10): a square wave, or a triangle where a level
        # or an integral action between integrates it, its edges through a lag
        return (
            replace(
                first,
                shape="square" if shape < 0.7 else "triangle",
                duty=float(rng.uniform(*LIMIT_CYCLE_DUTY)),
                edge_lag_s=period * _log_uniform(rng, *LIMIT_CYCLE_EDGE_LAG),
            ),
        )
    if rng.uniform() < 0.3:
        # the third harmonic a third of the fundamental, at the same place (version 11: it was
        # a third of the PV-unit amplitude whichever place the load entered)
        return (first, replace(first, sine_amplitude=size / 3.0, sine_period_s=period / 3.0))
    return (first,)


def _set_points(
    rng: np.random.Generator, kind: str, dur: float, ts: float
) -> tuple[tuple[float, float], ...]:
    """Set-point moves (time s, value % of span) around 50 %: steps, ramps (staircases) or a
    cascade master's slowly wandering output."""
    if kind == "steps":
        n = int(rng.integers(1, 7))
        times = np.sort(rng.uniform(0.05, 0.95, n)) * dur
        vals = 50.0 + rng.choice([-1.0, 1.0], n) * rng.uniform(1.0, 6.0, n)
        return tuple(zip(times.tolist(), vals.tolist(), strict=True))
    if kind == "ramps":
        start, length = rng.uniform(0.05, 0.6) * dur, rng.uniform(0.1, 0.3) * dur
        end = float(rng.uniform(-6.0, 6.0))
        k = max(2, min(200, int(length / ts)))
        return tuple((start + length * i / k, 50.0 + end * (i + 1) / k) for i in range(k))
    if kind == "cascade":
        k = max(2, min(400, int(dur / ts / 5)))
        walk = np.cumsum(rng.normal(0.0, 3.0 / math.sqrt(k), k))
        return tuple((dur * i / k, 50.0 + float(walk[i])) for i in range(k))
    return ()


def draw_case(seed: int, index: int, attempts: int = 20) -> tuple[CorpusCase, LoopRecord]:
    """Window ``index`` of corpus ``seed`` and its simulated record: the first of up to
    ``attempts`` draws whose label shows in the record (``VISIBLE``, output limits)."""
    return draw_cases(seed, [index], attempts)[0]


def draw_cases(
    seed: int, indices: Sequence[int], attempts: int = 20
) -> list[tuple[CorpusCase, LoopRecord]]:
    """``[draw_case(seed, i, attempts) for i in indices]``, the same windows bit for bit,
    simulated side by side (``iter_cases``)."""
    drawn = {i: (case, rec) for i, case, rec in iter_cases(seed, indices, attempts)}
    return [drawn[i] for i in indices]


def iter_cases(
    seed: int, indices: Iterable[int], attempts: int = 20, pass_samples: int = BATCH_SAMPLES
) -> Iterator[tuple[int, CorpusCase, LoopRecord]]:
    """Windows ``indices`` of corpus ``seed`` as ``draw_case`` draws them, each with its
    index, in the order they are settled. Each pass simulates side by side
    (``batch_loop.simulate_loops``) the next draws of the windows not yet shown and as many
    new windows as ``pass_samples`` holds, and from ``SPECULATIVE_TWINS`` draws on every
    draw's twin beside them: the twin of a draw that fails before it is weighed is then
    simulated for nothing, which costs less than another pass. A window whose ``attempts``
    draws all fail keeps its last."""
    fresh = iter(dict.fromkeys(indices))
    retry: list[tuple[int, int]] = []
    while True:
        draws: list[tuple[int, int, CorpusCase]] = []
        budget = 0
        while budget < pass_samples:
            if retry:
                i, attempt = retry.pop()
            elif (nxt := next(fresh, None)) is not None:
                i, attempt = nxt, 0
            else:
                break
            case = _draw(np.random.default_rng([seed, i, attempt]), i, CLASSES[i % len(CLASSES)])
            draws.append((i, attempt, case))
            budget += (1 + (case.twin is not None)) * (
                case.config.n_samples + case.config.warmup_samples
            )
        if not draws:
            return
        # a few draws (one window's) are stepped alone: a twin is then simulated only once
        # its draw is plausible, as draw_case always did
        ahead = len(draws) >= SPECULATIVE_TWINS
        twins = [case.twin for _, _, case in draws if case.twin is not None] if ahead else []
        recs = simulate_loops([case.config for _, _, case in draws] + twins)
        twin_recs = iter(recs[len(draws) :])
        for (i, attempt, case), rec in zip(draws, recs, strict=False):
            twin = next(twin_recs) if ahead and case.twin is not None else None
            shown = _plausible(case, rec)
            if shown and case.twin is not None:
                shown = _beside_twin(
                    case, rec, twin if twin is not None else simulate_loop(case.twin)
                )
            if shown or attempt + 1 >= attempts:
                yield i, case, rec
            else:
                retry.append((i, attempt + 1))


SPECULATIVE_TWINS = 32
"""From this many draws a pass simulates every twin beside its draw (``iter_cases``)."""

CHUNK_WINDOWS = 4000
"""Windows one worker draws side by side at most (``window_chunks``): a pass of
``iter_cases`` holds about 900, and the later passes take the retries of the earlier."""


def window_chunks(seed: int, first: int, n: int, jobs: int) -> list[tuple[int, int, int]]:
    """Windows ``first``..n-1 of corpus ``seed`` in contiguous chunks ``(seed, start, stop)``
    of ``CHUNK_WINDOWS`` at most, at least one per job."""
    size = max(1, min(CHUNK_WINDOWS, -(-(n - first) // max(jobs, 1))))
    return [(seed, a, min(a + size, n)) for a in range(first, n, size)]


def read_chunk(
    read: Callable[[int, int, CorpusCase, LoopRecord], T],
    chunk: tuple[int, int, int],
    each: Callable[[], None] | None = None,
) -> list[T]:
    """``read(seed, index, case, record)`` of every window of a ``window_chunks`` chunk, in
    index order; each record is dropped once read, and ``each()`` called (a progress count)."""
    seed, start, stop = chunk
    got = {}
    for i, case, rec in iter_cases(seed, range(start, stop)):
        got[i] = read(seed, i, case, rec)
        if each is not None:
            each()
    return [got[i] for i in range(start, stop)]


def _clamp_share(op: np.ndarray, limit: float | None) -> float:
    if limit is None:
        return 0.0
    return float(np.mean(np.abs(op - limit) <= 1e-9))


def _plausible(case: CorpusCase, rec: LoopRecord) -> bool:
    """Whether the record can show its label before any twin is weighed: the output rests
    at its limit for 20 % to ``CLAMP_SUPPORT`` of a saturated window (the learned decision is
    not asked beyond) and for at most 10 % of any other; a fault's error stands out of the
    noise (``VISIBLE``); a sticky valve sticks and slips at least twice. A window with a twin
    shows its label only if ``_beside_twin`` holds too."""
    c = case.config.controller
    limits = [v for v in (c.op_max, c.op_min) if 0.0 < v < 100.0]
    ends = [float(np.mean(rec.op >= 99.99)), float(np.mean(rec.op <= 0.01))]
    share = max([_clamp_share(rec.op, v) for v in limits] + ends)
    if case.cause == "saturation":
        return 0.2 <= share <= CLAMP_SUPPORT
    if share > 0.1:
        return False
    if not np.all(np.isfinite(rec.pv)) or float(np.ptp(rec.op)) < 1e-6:
        return False
    noise = max(case.config.noise_std, 1e-9)
    if case.cause in ("stiction", "aggressive_tuning", "external_disturbance"):
        e = rec.sp - rec.pv
        if float(np.std(e - np.mean(e))) < VISIBLE * noise:
            return False
    if case.cause == "stiction":
        moves = np.abs(np.diff(rec.mv)) > 1e-9
        starts = int(np.sum(moves[1:] & ~moves[:-1]))
        if starts < 2 and case.family["valve"] != "backlash":
            return False
    return True


def _beside_twin(case: CorpusCase, rec: LoopRecord, twin: LoopRecord) -> bool:
    """Whether the fault shows against its twin's record (``VISIBLY_FAULTY``)."""
    shown = fault_and_twin(case, rec, twin)
    if shown is None:  # no twin: nothing to weigh
        return True
    fault, without = shown
    if case.cause == "aggressive_tuning":
        return fault >= VISIBLY_FAULTY**2 * without
    return fault >= VISIBLY_FAULTY * without


def fault_and_twin(
    case: CorpusCase, rec: LoopRecord, twin: LoopRecord | None = None
) -> tuple[float, float] | None:
    """What ``VISIBLY_FAULTY`` weighs for a window and its twin (the same loop without the
    fault; its record ``twin``, simulated here when not given): the control error's σ (%), or
    for a loop near its stability limit its ringing power (``ringing_power``); None for a
    window without a twin (ok, saturation). ``benchmarks/cause_model_accuracy.py
    --strength`` reads the learned decision's accuracy against their ratio."""
    if case.twin is None:
        return None
    if twin is None:
        twin = simulate_loop(case.twin)
    e, e_twin = rec.sp - rec.pv, twin.sp - twin.pv
    if case.cause == "aggressive_tuning":
        ts, tu = case.config.sample_time_s, case.ultimate_period_s
        return ringing_power(e, ts, tu), ringing_power(e_twin, ts, tu)
    return float(np.std(e)), float(np.std(e_twin))


def ringing_power(e: np.ndarray, ts: float, tu: float) -> float:
    """The control error's power (Hann-windowed periodogram, %² summed over its bins) at half
    to twice the ultimate frequency 1/``tu`` (``ts``, ``tu`` in s), where a loop near its
    stability limit rings: only its ratio to another record's of the same length means
    anything."""
    power = hann_power(e)
    f = np.fft.rfftfreq(e.size, ts)
    return float(power[(f >= 0.5 / tu) & (f <= 2.0 / tu)].sum())


def _draw(rng: np.random.Generator, index: int, cause: str) -> CorpusCase:
    ts = _log_uniform(rng, 0.1, 60.0)
    pkind = str(rng.choice(FAMILIES["process"], p=[0.3, 0.2, 0.2, 0.1, 0.2]))
    proc, loop_type = _process(rng, pkind, ts)
    n = int(_log_uniform(rng, MIN_SAMPLES, MAX_SAMPLES))
    dur = n * ts
    noise = _log_uniform(rng, 0.02, 1.0)
    tc = _log_uniform(rng, 0.7, 2.5)
    pi = simc_pi_tc(proc, tc)
    ku, tu = ultimate_gain(proc, pi.Ti_s, ts)
    # PV units a % of travel moves within the loop's time scale: loads are sized against the
    # noise they must stand out of
    gain = abs(proc.K) * (tu if proc.kind == "integrating" else 1.0)
    load_kind = str(rng.choice(FAMILIES["load"][:4]))
    load_size = _log_uniform(rng, 1.0, 20.0) * noise / gain
    # every plant loop also sees small coloured loads from everywhere else
    background = _nuisance_load(
        rng, "coloured", dur, tu, _log_uniform(rng, 0.3, 3.0) * noise / gain
    )
    loads: tuple[Disturbance, ...] = (_nuisance_load(rng, load_kind, dur, tu, load_size),)
    sp_kind = str(rng.choice(FAMILIES["sp"], p=[0.35, 0.35, 0.15, 0.15]))
    sp_steps = _set_points(rng, sp_kind, dur, ts)
    valve, S, J, spread = "linear", 0.0, 0.0, 0.0
    good = pi  # a mistuned window's twin has this controller
    periodic = 0  # a disturbed window's first loads are the periodic ones
    if cause == "stiction":
        valve = str(rng.choice(FAMILIES["valve"][1:]))
        S = _log_uniform(rng, 0.2, 10.0)
        J = 0.0 if valve == "backlash" else float(rng.uniform(0.0, 1.0)) * S
        # half the sticky valves' friction varies from stop to stop, up to ±30 % (one σ)
        spread = float(rng.uniform(0.0, 0.3)) if rng.uniform() < 0.5 else 0.0
        # the cycle a sticky valve drives moves PV by about the gain times the band: a noise
        # larger than that hides the fault, which no record can then show
        swing = S * (proc.K * 20.0 * ts if proc.kind == "integrating" else proc.K)
        noise = min(noise, swing / _log_uniform(rng, 2.0, 20.0))
        load_size = min(load_size, S, _log_uniform(rng, 1.0, 20.0) * noise / gain)
        loads = (_nuisance_load(rng, load_kind, dur, tu, load_size),)
    elif cause == "aggressive_tuning":
        pi = replace(pi, Kc=float(rng.uniform(0.7, 0.95)) * ku)
        # a loop close to its stability limit rings at its own period on whatever load comes
        loads = (
            _nuisance_load(rng, "coloured", dur, tu, _log_uniform(rng, 1.0, 6.0) * noise / gain),
        )
    elif cause == "sluggish_tuning":
        # as slow as plants run them (version 8; version 7 stopped at Kc × 0.08, Ti × 6)
        pi = replace(pi, Kc=pi.Kc * _log_uniform(rng, 0.03, 0.35),
                     Ti_s=pi.Ti_s * _log_uniform(rng, 2.0, 30.0))  # fmt: skip
        if sp_kind == "constant":
            # a sluggish loop shows only in how it answers a load or a set-point move
            loads = (_nuisance_load(rng, "steps", dur, tu, 2.0 * load_size),)
    elif cause == "external_disturbance":
        load_kind = "periodic"
        period = min(_log_uniform(rng, 0.3, 20.0) * tu, dur / 5.0)
        amp = _log_uniform(rng, 3.0, 15.0) * noise
        cycles = _periodic_load(rng, max(period, 4 * ts), amp, gain)
        periodic = len(cycles)
        loads = (*cycles, loads[0])
    tuning = {"ok": "simc", "aggressive_tuning": "near_limit", "sluggish_tuning": "sluggish"}.get(
        cause, "simc"
    )
    if cause in DETUNABLE and rng.uniform() < 0.5:
        # plants run many loops detuned: a sticky valve then slips a few times an hour instead
        # of cycling, a disturbance passes through a slow loop, whatever the fault
        tuning = "detuned"
        pi = replace(pi, Kc=pi.Kc * _log_uniform(rng, 0.03, 0.6),
                     Ti_s=pi.Ti_s * _log_uniform(rng, 1.0, 30.0))  # fmt: skip
    limit_kind = str(rng.choice(FAMILIES["limit"], p=[0.4, 0.2, 0.4]))
    u0 = float(rng.uniform(15.0, 85.0))
    steady = steady_op(proc, 50.0, 0.0, u0)
    op_min, op_max = 0.0, 100.0
    high = rng.uniform() < 0.7
    if cause == "saturation":
        limit = (
            float(rng.uniform(5.0, 95.0)) if limit_kind != "at_100" else (100.0 if high else 0.0)
        )
        if limit_kind == "free":
            limit_kind = "anywhere"
        # a load early on asks for 2-15 % more output than the limit gives
        need = (
            (limit + _log_uniform(rng, 2.0, 15.0))
            if high
            else (limit - _log_uniform(rng, 2.0, 15.0))
        )
        at = float(rng.uniform(0.05, 0.5)) * dur
        u0 = float(np.clip(limit - (10.0 if high else -10.0), 5.0, 95.0))
        steady = steady_op(proc, 50.0, 0.0, u0)
        loads = (Disturbance(steps=((at, steady - need),)), *loads[1:])
        sp_steps = tuple((t, v) for t, v in sp_steps if t < at)
        if high:
            op_max = limit
        else:
            op_min = limit
    elif limit_kind == "anywhere":
        margin = _log_uniform(rng, 3.0, 30.0)
        if high:
            op_max = min(99.0, steady + margin)
        else:
            op_min = max(1.0, steady - margin)
    if proc.K < 0 or rng.uniform() < 0.2:
        # a direct-acting loop: the process gain and the controller's both negative
        proc = replace(proc, K=-abs(proc.K))
        pi = replace(pi, Kc=-abs(pi.Kc))
        u0 = 100.0 - u0
        op_min, op_max = 100.0 - op_max, 100.0 - op_min
        loads = tuple(_negate(d) for d in loads)
    pi = PIController(Kc=pi.Kc, Ti_s=pi.Ti_s, op_min=op_min, op_max=op_max)
    loads = (*loads, background)
    rec_kind = str(rng.choice(FAMILIES["recording"], p=[0.4, 0.2, 0.2, 0.2]))
    quantum = _log_uniform(rng, 0.5, 3.0) * noise if rec_kind == "quantised" else 0.0
    compressed = rec_kind in ("compressed", "interpolated")
    compression = _log_uniform(rng, 0.5, 3.0) * noise if compressed else 0.0
    op_compression = _log_uniform(rng, 0.02, 0.3) if rec_kind == "interpolated" else 0.0
    # transmitter damping or a DCS PV filter on two loops in five
    pv_filter = _log_uniform(rng, 0.5, 3.0) * ts if rng.uniform() < 0.4 else 0.0
    warmup = min(20_000, int(20 * tu / ts) + 200)
    # disturbances run on the simulation's clock, which starts with the warm-up
    loads = tuple(replace(d, steps=tuple((t + warmup * ts, v) for t, v in d.steps)) for d in loads)
    cfg = LoopConfig(
        process=proc,
        controller=pi,
        valve=valve,  # type: ignore[arg-type]
        S=S,
        J=J,
        friction_spread=spread,
        disturbances=loads,
        noise_std=noise,
        sp_steps=sp_steps,
        u0=u0,
        sample_time_s=ts,
        n_samples=n,
        warmup_samples=warmup,
        pv_quantum=quantum,
        pv_compression=compression,
        interpolated=rec_kind == "interpolated",
        op_compression=op_compression,
        pv_filter_s=pv_filter,
        seed=int(rng.integers(1 << 30)),
    )
    # drawn after everything else, so a window in automatic is the window of version 10 (but
    # for the third harmonic's size, ``_periodic_load``)
    operation = str(rng.choice(FAMILIES["operation"], p=OPERATION_SHARES))
    if operation != "auto":
        share = _log_uniform(rng, *(MANUAL_SHARE if operation == "manual" else FROZEN_SHARE))
        start = float(rng.uniform(0.0, 1.0 - share)) * dur
        stretch = ((start, start + share * dur),)
        if operation == "manual":
            cfg = replace(cfg, manual=stretch)
        else:
            cfg = replace(cfg, frozen_pv=stretch)
    twin = None
    if cause == "stiction":
        twin = replace(cfg, valve="linear", S=0.0, J=0.0)
    elif cause in ("aggressive_tuning", "sluggish_tuning"):
        kc = math.copysign(good.Kc, pi.Kc)
        twin = replace(cfg, controller=PIController(Kc=kc, Ti_s=good.Ti_s, op_min=op_min,
                                                    op_max=op_max))  # fmt: skip
    elif cause == "external_disturbance":
        twin = replace(cfg, disturbances=cfg.disturbances[periodic:])
    family = {"process": pkind, "valve": valve, "load": load_kind, "sp": sp_kind, "tuning": tuning,
              "limit": limit_kind, "recording": rec_kind, "operation": operation}  # fmt: skip
    return CorpusCase(index, cause, loop_type, cfg, family, tu, twin)


def _negate(d: Disturbance) -> Disturbance:
    """The same disturbance acting the other way (a direct-acting loop's load)."""
    return replace(
        d,
        sine_amplitude=-d.sine_amplitude,
        steps=tuple((t, -s) for t, s in d.steps),
    )


def corpus(seed: int, n: int, start: int = 0) -> Iterator[tuple[CorpusCase, LoopRecord]]:
    """Windows ``start`` to ``start + n`` of corpus ``seed`` with their records."""
    for i in range(start, start + n):
        yield draw_case(seed, i)
