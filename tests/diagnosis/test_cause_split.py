"""diagnosis/cause_split.py: aggressive tuning or an external disturbance, also when the
disturbance comes at the loop's own period (issue 25 item 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

from plantcheck.diagnosis import Diagnosis, diagnose
from plantcheck.diagnosis.cause_split import envelope_spread
from plantcheck.simulator.cases import generate_cases, process_setup
from plantcheck.simulator.loop import Disturbance, LoopConfig, simulate_loop


def test_envelope_of_a_sine_is_steady_and_of_narrow_band_noise_spread() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(6000, dtype=np.float64)
    sine = np.sin(2 * np.pi * t / 50.0) + 0.2 * rng.normal(size=t.size)
    spread_sine = envelope_spread(sine, 1.0, 50.0)
    assert spread_sine is not None and spread_sine.cv < 0.15
    # white noise through a resonance (ζ = 0.05 at a 50-sample period): Rayleigh envelope
    w = 2 * np.pi / 50.0
    r = np.exp(-0.05 * w)
    ringing = lfilter([1.0], [1.0, -2 * r * np.cos(w), r * r], rng.normal(size=t.size))
    spread_ring = envelope_spread(ringing, 1.0, 50.0)
    assert spread_ring is not None and 0.35 < spread_ring.cv < 0.7
    # the ringing stands far above its white part: taking the noise out keeps it spread
    assert spread_ring.cv_signal > 0.35


def test_the_noise_is_taken_out_of_a_steady_cycles_spread() -> None:
    """A sine 3 x over the band-passed white noise spreads its half-cycle amplitudes as
    ringing does (Rice 1944); without the noise's share it is steady again."""
    rng = np.random.default_rng(2)
    t = np.arange(6000, dtype=np.float64)
    period = 20.0
    sigma_white = 1.0
    sigma_band = sigma_white * np.sqrt(2 * (1.6 - 1 / 1.6) / period)
    x = 3 * sigma_band * np.sin(2 * np.pi * t / period) + rng.normal(0, sigma_white, t.size)
    spread = envelope_spread(x, 1.0, period)
    assert spread is not None
    assert spread.cv > 0.25
    assert spread.cv_signal < 0.15
    # barely over the noise (Rayleigh-like envelope) the spread is left as measured
    weak = 0.5 * sigma_band * np.sin(2 * np.pi * t / period) + rng.normal(0, sigma_white, t.size)
    spread_weak = envelope_spread(weak, 1.0, period)
    assert spread_weak is not None and spread_weak.cv_signal == spread_weak.cv


def _sine_load_diagnosis(
    kind: str, amplitude: float, multiple: float, *, noise: float, seed: int
) -> Diagnosis:
    """A well-tuned loop of ``kind`` under a sinusoidal load of ``amplitude`` % at
    ``multiple`` × its ultimate period, 3,600 samples, diagnosed."""
    su = process_setup(kind)
    cfg = LoopConfig(
        process=su.process,
        controller=su.pi,
        sample_time_s=su.ts,
        n_samples=3600,
        warmup_samples=int(20 * su.tu / su.ts) + 200,
        noise_std=noise,
        seed=seed,
        disturbances=(
            Disturbance(where="load", sine_amplitude=amplitude, sine_period_s=multiple * su.tu),
        ),
    )
    run = simulate_loop(cfg)
    return diagnose(run.pv, run.op, su.ts, sp=run.sp, loop_type=kind, quantify=False)


@pytest.mark.parametrize("multiple", [0.7, 1.0, 1.5])
def test_a_disturbance_at_the_loops_own_period_is_external(multiple: float) -> None:
    """A sinusoidal load at 0.7-1.5 × the ultimate period of a well-tuned loop: the OP-PV
    phase reads like the loop's own oscillation, the steady amplitude does not."""
    d = _sine_load_diagnosis("pressure", 4.0, multiple, noise=0.2, seed=7)
    assert d.cause == "external_disturbance", d.notes


@pytest.mark.parametrize("kind", ["pressure", "temperature", "flow"])
def test_a_disturbance_near_the_loops_period_is_external_in_heavy_noise(kind: str) -> None:
    """A sinusoidal load at 0.6 × the ultimate period, its cycle in PV only 2-5 × the
    band-passed noise (σ 0.5 %): the noise alone spreads the half-cycle amplitudes as ringing
    does. Before the noise's share was taken out, all 12 read aggressive tuning."""
    for seed in range(1, 5):
        d = _sine_load_diagnosis(kind, 2.0, 0.6, noise=0.5, seed=seed)
        assert d.cause == "external_disturbance", (seed, d.notes)


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


def test_one_stiction_test_alone_leaves_the_split_to_read_the_cycle() -> None:
    """An aggressive level loop whose only stiction vote is the curve fit (a lightly damped
    linear cycle passes it too, and no other test applies against it): the vote is no
    verdict, so the split reads the cycle instead of calling the cause unknown."""
    case = next(
        c
        for c in generate_cases(seed=2, lengths=(1000, 5000))
        if c.cause == "aggressive_tuning" and c.name.endswith("level-n5000-noise0.05-r0")
    )
    run = simulate_loop(case.config)
    d = diagnose(run.pv, run.op, case.config.sample_time_s, sp=run.sp, loop_type="level")
    assert d.cause == "aggressive_tuning", d.notes
    assert any("stiction not confirmed (1 test for, 0 against)" in n for n in d.notes), d.notes


def test_the_shipped_rice_table_is_the_one_scipy_computes_bit_for_bit() -> None:
    """The envelope table ships as data (scipy.special's import cost a diagnosis 0.15 s):
    what ``python -m plantcheck.service.rice_table`` writes, exactly."""
    from plantcheck.diagnosis.cause_split import RICE_NU, _rice_table
    from plantcheck.service.rice_table import rice_envelope_mean

    shipped, _ = _rice_table()
    assert np.array_equal(shipped, rice_envelope_mean(RICE_NU))
    assert shipped[0] == np.sqrt(np.pi / 2) and np.all(np.diff(shipped) > 0)


def test_rebuilding_the_rice_table_into_a_missing_folder_is_refused_by_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from plantcheck.service.rice_table import main

    out = tmp_path / "missing" / "rice.npz"
    with pytest.raises(SystemExit) as stop:
        main(["--out", str(out)])
    assert stop.value.code == 2
    assert f"cannot write --out {out}" in capsys.readouterr().err
    main(["--out", str(tmp_path / "rice.npz")])
    assert (tmp_path / "rice.npz").is_file()
