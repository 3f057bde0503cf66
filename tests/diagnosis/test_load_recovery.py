"""diagnosis/load_recovery.py: load responses judge the tuning where no set-point step does,
and a healthy slow loop is not sluggish (issue 25 item 2)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.load_recovery import load_recoveries, recovery_slowness
from plantcheck.simulator.cases import process_setup
from plantcheck.simulator.loop import Disturbance, LoopConfig, simulate_loop

NO_STEPS = np.zeros(0, dtype=np.int64)


def _loaded(pname: str, sluggish: bool, noise: float = 0.2, seed: int = 3) -> LoopConfig:
    """A constant set point and two load steps of 6 % of the output, far apart."""
    su = process_setup(pname)
    pi = replace(su.pi, Kc=0.2 * su.pi.Kc, Ti_s=5 * su.pi.Ti_s) if sluggish else su.pi
    n = 3600
    warmup = int(20 * su.tu / su.ts) + 200
    t0, dur = warmup * su.ts, n * su.ts  # load times count from the warm-up's start
    return LoopConfig(
        process=su.process,
        controller=pi,
        sample_time_s=su.ts,
        n_samples=n,
        warmup_samples=warmup,
        noise_std=noise,
        seed=seed,
        disturbances=(
            Disturbance(where="load", steps=((t0 + 0.2 * dur, 6.0), (t0 + 0.6 * dur, -6.0))),
        ),
    )


@pytest.mark.parametrize("pname", ["flow", "pressure", "temperature", "composition"])
def test_well_tuned_loops_recover_about_as_fast_as_the_load_pushed(pname: str) -> None:
    """SIMC tuning, whether the process takes seconds or minutes: not sluggish by its load
    recoveries. (The idle index still reads the temperature loop as sluggish; a fast recovery
    does not overrule it: tried, that cost one sluggish window in each generated set.)"""
    cfg = _loaded(pname, sluggish=False)
    run = simulate_loop(cfg)
    rec = load_recoveries(run.pv, run.sp, NO_STEPS)
    assert len(rec) >= 2
    slowness = recovery_slowness(rec)
    assert slowness is not None and slowness < 3.0
    d = diagnose(run.pv, run.op, cfg.sample_time_s, sp=run.sp, loop_type="other", quantify=False)
    assert not any("load recoveries" in n for n in d.notes)


@pytest.mark.parametrize("pname", ["flow", "pressure", "temperature"])
@pytest.mark.parametrize("noise", [0.2, 0.5])
def test_sluggish_loops_show_it_in_their_load_recoveries(pname: str, noise: float) -> None:
    """Gain × 0.2 and integral time × 5 (methods §9.1): the error comes back many times slower
    than it went out, under noise that hides it from the idle index."""
    cfg = _loaded(pname, sluggish=True, noise=noise)
    run = simulate_loop(cfg)
    d = diagnose(run.pv, run.op, cfg.sample_time_s, sp=run.sp, loop_type="other", quantify=False)
    assert d.cause == "sluggish_tuning", d.notes
    assert d.indices["load_recovery_slowness"] > 3.0
    assert any("load recoveries" in n for n in d.notes)


def test_responses_a_set_point_step_starts_are_left_out() -> None:
    """A set-point step moves the error as a load does; its response is the step's to judge."""
    n = 2000
    k = np.arange(n)
    sp = np.where(k < 500, 50.0, 55.0)
    pv = 50.0 + 5.0 * (1.0 - np.exp(-np.maximum(k - 500, 0) / 200.0))
    pv += np.random.default_rng(1).normal(0.0, 0.05, n)
    assert load_recoveries(pv, sp, np.array([500])) == ()
    assert load_recoveries(pv, sp, NO_STEPS) != ()


def test_a_quiet_loop_has_no_load_response() -> None:
    rng = np.random.default_rng(2)
    pv = 50.0 + rng.normal(0.0, 0.5, 3000)
    assert load_recoveries(pv, np.full(3000, 50.0), NO_STEPS) == ()
    assert recovery_slowness(()) is None
