"""diagnosis/cause_split.py: aggressive tuning or an external disturbance, also when the
disturbance comes at the loop's own period (issue 25 item 4)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.cause_split import envelope_cv
from plantcheck.simulator.cases import process_setup
from plantcheck.simulator.loop import Disturbance, LoopConfig, simulate_loop


def test_envelope_of_a_sine_is_steady_and_of_narrow_band_noise_spread() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(6000, dtype=np.float64)
    sine = np.sin(2 * np.pi * t / 50.0) + 0.2 * rng.normal(size=t.size)
    cv_sine = envelope_cv(sine, 1.0, 50.0)
    assert cv_sine is not None and cv_sine < 0.15
    # white noise through a resonance (ζ = 0.05 at a 50-sample period): Rayleigh envelope
    w = 2 * np.pi / 50.0
    r = np.exp(-0.05 * w)
    ringing = lfilter([1.0], [1.0, -2 * r * np.cos(w), r * r], rng.normal(size=t.size))
    cv_ring = envelope_cv(ringing, 1.0, 50.0)
    assert cv_ring is not None and 0.35 < cv_ring < 0.7


@pytest.mark.parametrize("multiple", [0.7, 1.0, 1.5])
def test_a_disturbance_at_the_loops_own_period_is_external(multiple: float) -> None:
    """A sinusoidal load at 0.7-1.5 × the ultimate period of a well-tuned loop: the OP-PV
    phase reads like the loop's own oscillation, the steady amplitude does not."""
    su = process_setup("pressure")
    cfg = LoopConfig(
        process=su.process,
        controller=su.pi,
        sample_time_s=su.ts,
        n_samples=3600,
        warmup_samples=int(20 * su.tu / su.ts) + 200,
        noise_std=0.2,
        seed=7,
        disturbances=(
            Disturbance(where="load", sine_amplitude=4.0, sine_period_s=multiple * su.tu),
        ),
    )
    run = simulate_loop(cfg)
    d = diagnose(run.pv, run.op, su.ts, sp=run.sp, loop_type="pressure", quantify=False)
    assert d.cause == "external_disturbance", d.notes


def test_an_aggressive_loop_ringing_on_random_loads_is_tuning() -> None:
    su = process_setup("pressure")
    cfg = LoopConfig(
        process=su.process,
        controller=type(su.pi)(Kc=0.9 * su.ku, Ti_s=su.pi.Ti_s),
        sample_time_s=su.ts,
        n_samples=3600,
        warmup_samples=int(20 * su.tu / su.ts) + 200,
        noise_std=0.2,
        seed=8,
        disturbances=(Disturbance(filtered_noise_std=1.0, filtered_noise_tau_s=su.tu),),
    )
    run = simulate_loop(cfg)
    d = diagnose(run.pv, run.op, su.ts, sp=run.sp, loop_type="pressure", quantify=False)
    assert d.cause == "aggressive_tuning", d.notes
