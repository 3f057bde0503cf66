"""diagnosis/acf_decay.py: the decay ratio of the ACF (Miao & Seborg 1999) tells a lightly
damped loop from one that damps its own cycle out; the chain calls only the first aggressive.

A SIMC-tuned loop whose dead time is one sample or so has a spectral bump at its own frequency
that the regularity test can read as an oscillation (issue 25: healthy loops must not be
called aggressive); its ACF dies out within a cycle."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import plant_window
from scipy.signal import lfilter

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.acf_decay import EXCESSIVE_DECAY_RATIO, acf_decay_ratio
from plantcheck.simulator.cases import simc_pi, ultimate_gain
from plantcheck.simulator.loop import Disturbance, LoopConfig, PIController, Process, simulate_loop


def _resonance(
    pole_radius: float, period: float = 20.0, n: int = 4000, seed: int = 0
) -> np.ndarray:
    """White noise through a resonance (AR(2) poles at ``pole_radius``, ``period`` samples)."""
    w = np.random.default_rng(seed).normal(size=n)
    a1 = -2.0 * pole_radius * np.cos(2.0 * np.pi / period)
    return lfilter([1.0], [1.0, a1, pole_radius**2], w)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_lightly_damped_resonance_is_excessive_and_a_damped_one_is_not(seed: int) -> None:
    ringing = _resonance(0.98, seed=seed)
    damped = _resonance(0.85, seed=seed)
    r_ringing, r_damped = acf_decay_ratio(ringing), acf_decay_ratio(damped)
    assert r_ringing is not None and r_ringing > 0.7
    assert r_damped is not None and r_damped < EXCESSIVE_DECAY_RATIO


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_white_measurement_noise_does_not_make_a_ringing_loop_look_damped(seed: int) -> None:
    """Noise adds to the ACF's lag 0 only; without the rescaling a noise as large as the
    ringing halves every other lag and R with it."""
    ringing = _resonance(0.98, seed=seed)
    noise = np.random.default_rng(seed + 10).normal(scale=float(np.std(ringing)), size=4000)
    ratio = acf_decay_ratio(ringing + noise)
    assert ratio is not None and ratio > 0.7


def test_a_sustained_cycle_reads_near_one_and_white_noise_near_zero() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(4000)
    cycle = acf_decay_ratio(np.sin(2.0 * np.pi * t / 25.0) + rng.normal(scale=0.5, size=t.size))
    assert cycle is not None and cycle > 0.9
    white = acf_decay_ratio(rng.normal(size=4000))
    assert white is None or white < 0.2


def test_a_record_without_four_acf_zero_crossings_has_no_ratio() -> None:
    assert acf_decay_ratio(np.linspace(0.0, 1.0, 300) ** 2) is None


FAST_LOOPS = {
    # dead time about one sample: the closed loop's own frequency sits a few samples long
    "temperature": (Process("fopdt", K=0.7, tau_s=120.0, theta_s=8.0), 6.4),
    "level": (Process("integrating", K=0.2, theta_s=1.0), 1.0),
}


def _fast_loop(loop_type: str, noise: float, seed: int, ku_fraction: float | None) -> str:
    """The cause the chain gives a SIMC PI (or one at ``ku_fraction`` of the ultimate gain,
    under coloured load, as the generated aggressive loops) on a fast-sampled process."""
    proc, ts = FAST_LOOPS[loop_type]
    n = 3600
    pi = simc_pi(proc)
    ku, tu = ultimate_gain(proc, pi.Ti_s, ts)
    if ku_fraction is None:
        rng = np.random.default_rng(seed)
        times = np.sort(rng.uniform(0.0, n * ts, 4)).tolist()
        sizes = rng.normal(0.0, 1.0, 4).tolist()
        loads = Disturbance(steps=tuple(zip(times, sizes, strict=True)))
    else:
        pi = PIController(Kc=ku_fraction * ku, Ti_s=pi.Ti_s)
        loads = Disturbance(filtered_noise_std=1.0, filtered_noise_tau_s=tu)
    cfg = LoopConfig(
        process=proc,
        controller=pi,
        disturbances=(loads,),
        noise_std=noise,
        sample_time_s=ts,
        n_samples=n,
        seed=seed,
    )
    r = simulate_loop(cfg)
    return diagnose(r.pv, r.op, ts, sp=r.sp, loop_type=loop_type, quantify=False).cause


@pytest.mark.parametrize("loop_type", sorted(FAST_LOOPS))
@pytest.mark.parametrize("noise", [0.05, 0.2, 0.5])
def test_healthy_fast_sampled_loops_are_not_called_aggressive(loop_type: str, noise: float) -> None:
    """Before the decay ratio, 5 of these 18 windows (seeds 1-3) read aggressive tuning."""
    causes = [_fast_loop(loop_type, noise, seed, None) for seed in (1, 2, 3)]
    assert causes == ["ok"] * 3


@pytest.mark.parametrize("loop_type", sorted(FAST_LOOPS))
@pytest.mark.parametrize("noise", [0.05, 0.5])
def test_aggressive_fast_sampled_loops_still_are(loop_type: str, noise: float) -> None:
    assert _fast_loop(loop_type, noise, 1, 0.9) == "aggressive_tuning"


def test_a_well_damped_cycle_of_unknown_cause_is_no_oscillation() -> None:
    """A healthy level loop whose noise-driven cycle the split could tie to nothing (it read
    ``oscillation_unknown_cause``) dies out within a cycle: judged as a quiet loop."""
    case = plant_window("ok-level-n2000-steps1-limit64-continuous-noise0.05-r1")
    r = simulate_loop(case.config)
    d = diagnose(r.pv, r.op, case.config.sample_time_s, sp=r.sp, loop_type="level", quantify=False)
    assert d.cause == "ok"
    assert not d.oscillating
    assert any("is well damped (ACF decay ratio" in n for n in d.notes)
