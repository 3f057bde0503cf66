"""The learned decision (issue 46): the simulated corpus, the exported trees, the calibrated
probabilities and their evidence, and the too-short rule."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from plantcheck.diagnosis import ChainParams, diagnose
from plantcheck.diagnosis.cause_model import CLAMP_SUPPORT, decide, shipped_cause_model
from plantcheck.diagnosis.chain import SHAPE_EVIDENCE, chain_evidence, chain_shape_input
from plantcheck.diagnosis.evidence import (
    EVIDENCE_VERSION,
    FEATURE_NAMES,
    FEATURES,
    evidence_vector,
)
from plantcheck.simulator.cases import simc_pi
from plantcheck.simulator.corpus import (
    CLASSES,
    FAMILIES,
    FROZEN_SHARE,
    MANUAL_SHARE,
    draw_case,
)
from plantcheck.simulator.loop import Disturbance, LoopConfig, Process, simulate_loop


def test_corpus_windows_are_reproducible_balanced_and_labelled_by_family() -> None:
    cases = [draw_case(7, i) for i in range(12)]
    assert Counter(c.cause for c, _ in cases) == {c: 2 for c in CLASSES}
    for case, rec in cases:
        assert set(case.family) == set(FAMILIES)
        assert all(case.family[k] in FAMILIES[k] for k in FAMILIES)
        assert rec.pv.size == case.config.n_samples and np.all(np.isfinite(rec.pv))
    again, rec2 = draw_case(7, 5)
    assert again.config == cases[5][0].config
    np.testing.assert_array_equal(rec2.pv, cases[5][1].pv)


def test_corpus_windows_hold_short_manual_and_frozen_stretches_their_twins_share() -> None:
    """Unflagged manual stretches of 2-9 % of the window (OP held) and frozen transmitters of
    1-4 % (PV held), inside the record, in windows of several classes."""
    seen: dict[str, set[str]] = {"manual": set(), "frozen": set()}
    for i in range(150):
        case, rec = draw_case(13, i)
        op = case.family["operation"]
        if op == "auto":
            assert not case.config.manual and not case.config.frozen_pv
            continue
        seen[op].add(case.cause)
        field = "manual" if op == "manual" else "frozen_pv"
        ((start, stop),) = getattr(case.config, field)
        span = case.config.n_samples * case.config.sample_time_s
        lo, hi = MANUAL_SHARE if op == "manual" else FROZEN_SHARE
        assert start >= 0.0 and stop <= span and lo <= (stop - start) / span <= hi
        k = slice(math.ceil(start / case.config.sample_time_s - 1e-9) + 1,
                  math.ceil(stop / case.config.sample_time_s - 1e-9))  # fmt: skip
        held = rec.op[k] if op == "manual" else rec.pv[k]
        # a compressing historian draws its own line through the hold
        if case.family["recording"] in ("continuous", "quantised"):
            assert np.ptp(held) == 0.0, case.family
        if case.twin is not None:  # the same operator and transmitter without the fault
            assert getattr(case.twin, field) == getattr(case.config, field)
    assert all(len(causes) >= 3 for causes in seen.values()), seen


def test_saturated_corpus_windows_rest_at_their_limit() -> None:
    for i in (5, 11, 17):
        case, rec = draw_case(3, i)
        assert case.cause == "saturation"
        c = case.config.controller
        at = np.isclose(rec.op, c.op_max) | np.isclose(rec.op, c.op_min)
        assert 0.2 <= float(np.mean(at)) <= CLAMP_SUPPORT, case.family


def test_the_shipped_model_reads_every_input_and_adds_up() -> None:
    """Saabas contributions and the trees' base values add up to the raw score, and the
    calibrated probabilities sum to one."""
    model = shipped_cause_model()
    assert model is not None, "diagnosis/models/cause_model.npz is missing: plantcheck model fit"
    assert model.features == FEATURE_NAMES and model.classes == CLASSES
    # fitted on the evidence this chain gathers: a version raised without a refit fails here
    assert model.meta["evidence_version"] == EVIDENCE_VERSION, "refit: plantcheck model fit"
    assert 0.2 < model.temperature < 5.0
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = rng.normal(size=len(FEATURE_NAMES))
        x[rng.uniform(size=x.size) < 0.3] = np.nan
        d = decide(model, x)
        np.testing.assert_allclose(d.base + d.contributions.sum(axis=1), d.raw, atol=1e-9)
        assert abs(float(d.probabilities.sum()) - 1.0) < 1e-12


def test_the_walk_scores_as_each_tree_read_alone() -> None:
    """``decide`` walks all trees at once on a laid-out copy of the nodes; each tree followed
    node by node from its root, missing inputs as LightGBM sends them, gives the same scores."""
    model = shipped_cause_model()
    assert model is not None
    rng = np.random.default_rng(1)
    for _ in range(3):
        x = rng.normal(size=len(FEATURE_NAMES))
        x[rng.uniform(size=x.size) < 0.3] = np.nan
        raw = np.zeros(len(CLASSES))
        for root, cls in zip(model.roots.tolist(), model.tree_class.tolist(), strict=True):
            node = root
            while model.feature[node] >= 0:
                v = x[model.feature[node]]
                if np.isnan(v) and model.nan_as_zero[node]:
                    v = 0.0
                left = model.default_left[node] if np.isnan(v) else v <= model.threshold[node]
                node = model.left[node] if left else model.right[node]
            raw[cls] += model.value[node]
        np.testing.assert_allclose(decide(model, x).raw, raw, atol=1e-9)


def _sticky() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    proc = Process("fopdt", K=1.0, tau_s=10.0, theta_s=2.0)
    cfg = LoopConfig(process=proc, controller=simc_pi(proc), valve="kano", S=4.0, J=2.0,
                     noise_std=0.05, n_samples=2000, warmup_samples=400, seed=3)  # fmt: skip
    r = simulate_loop(cfg)
    return r.pv, r.op, r.sp, 1.0


def test_a_diagnosis_weighs_the_evidence_the_corpus_gives_the_fit() -> None:
    """The fit learns from ``chain_evidence``; a learned diagnosis must weigh the same inputs.
    Until evidence version 8 the corpus skipped the evidence the rules' path did not need (the
    stiction tests wherever a period was found, the oscillation test on windows the window
    checks decided), which a diagnosis gathered: 124 of 299 calibration windows were weighed on
    inputs the fit never saw present for such windows. The shape network reads the window the
    window checks give (``chain_shape_input``), as the fit does."""
    model = shipped_cause_model()
    assert model is not None
    weighed = 0
    for i in range(40):
        case, rec = draw_case(202, i)
        ts = case.config.sample_time_s
        _, ev = chain_evidence(rec.pv, rec.op, ts, sp=rec.sp, loop_type=case.loop_type)
        if ev is None:
            continue
        d = diagnose(rec.pv, rec.op, ts, sp=rec.sp, loop_type=case.loop_type, quantify=False,
                     params=ChainParams(decide_by="learned"))  # fmt: skip
        if d.cause not in CLASSES:  # too short to judge or far from its baseline: re-read
            continue
        shape, judged = chain_shape_input(rec.pv, rec.op, rec.sp, loop_type=case.loop_type, ts=ts)
        assert judged
        probs = decide(model, evidence_vector(ev), shape).probabilities
        assert d.confidence == float(probs.max()), (i, case.family)
        weighed += 1
    assert weighed >= 30


def test_probabilities_and_evidence_in_the_json() -> None:
    pv, op, sp, ts = _sticky()
    for decide_by in ("rules", "learned"):
        d = diagnose(pv, op, ts, sp=sp, loop_type="flow", quantify=False,
                     params=ChainParams(decide_by=decide_by))  # fmt: skip
        out = d.to_dict()
        assert out["cause"] == "stiction", (decide_by, out["notes"])
        probs = out["probabilities"]
        assert set(probs) == set(CLASSES) and abs(sum(probs.values()) - 1.0) < 0.01
        # both rounded from the same probability: to 2 and to 3 decimals
        assert abs(out["confidence"] - probs["stiction"]) <= 0.0051
        names = {e["name"] for e in out["evidence"]}
        assert names and names <= {*FEATURES, SHAPE_EVIDENCE}
        sizes = [abs(e["contribution"]) for e in out["evidence"]]
        assert sizes == sorted(sizes, reverse=True)


def test_without_a_model_the_rules_decide_alone() -> None:
    pv, op, sp, ts = _sticky()
    d = diagnose(pv, op, ts, sp=sp, loop_type="flow", quantify=False,
                 params=ChainParams(cause_model=None))  # fmt: skip
    assert d.cause == "stiction" and d.probabilities is None and d.evidence is None


def test_a_window_clamped_beyond_the_corpus_keeps_the_window_checks_verdict() -> None:
    """A valve at its limit for the whole window (issue 25's plant windows) is not a window the
    corpus draws (clamped for at most ``CLAMP_SUPPORT`` of it): the model read such windows'
    constant OP as a sticky valve with p = 1.00. It is not asked there; within the corpus'
    share it is."""
    from plantcheck.simulator.plant_windows import generate_plant_window_cases

    learned = ChainParams(decide_by="learned")
    cases = generate_plant_window_cases(1, 1)
    saturated = [pc.case for pc in cases if pc.case.cause == "saturation"]
    read = 0
    for c in saturated:
        r = simulate_loop(c.config)
        d = diagnose(r.pv, r.op, c.config.sample_time_s, sp=r.sp, loop_type=c.loop_type,
                     quantify=False, params=learned)  # fmt: skip
        if d.indices["saturation_fraction"] <= CLAMP_SUPPORT:
            continue  # within the corpus' share: weighed
        assert d.cause == "saturation" and d.probabilities is None, (c.name, d.notes)
        assert any("is not asked" in n for n in d.notes), d.notes
        read += 1
        if read == 3:
            break
    assert read == 3
    case, rec = draw_case(3, 5)
    assert case.cause == "saturation"
    d = diagnose(rec.pv, rec.op, case.config.sample_time_s, sp=rec.sp, loop_type=case.loop_type,
                 quantify=False, params=learned)  # fmt: skip
    assert d.indices["saturation_fraction"] <= CLAMP_SUPPORT
    assert d.probabilities is not None and not any("is not asked" in n for n in d.notes)


def test_too_short_to_judge_is_not_ok() -> None:
    """Issue 46 item 4: a healthy loop's 200 samples do not show that it is healthy."""
    proc = Process("fopdt", K=1.0, tau_s=20.0, theta_s=5.0)
    cfg = LoopConfig(process=proc, controller=simc_pi(proc), noise_std=0.2, n_samples=3000,
                     disturbances=(Disturbance(filtered_noise_std=0.5),), seed=2)  # fmt: skip
    r = simulate_loop(cfg)
    long = diagnose(r.pv, r.op, 1.0, sp=r.sp, loop_type="temperature", quantify=False)
    assert long.cause == "ok", long.notes
    for n in (120, 199):
        short = diagnose(r.pv[:n], r.op[:n], 1.0, sp=r.sp[:n], loop_type="temperature")
        assert short.cause == "insufficient_data", short.notes
        assert any("300 needed" in note for note in short.notes)
        assert short.probabilities is None


def test_a_loop_far_from_its_own_normal_is_not_ok() -> None:
    """Issue 46 item 5: a healthy-looking loop whose error varies several times its baseline
    reads ``performance_degraded`` (or the cause the evidence supports), never ``ok``."""
    from plantcheck.diagnosis import baseline_from

    proc = Process("fopdt", K=1.0, tau_s=20.0, theta_s=5.0)

    def run(noise: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        load = (Disturbance(filtered_noise_std=0.3),)
        cfg = LoopConfig(process=proc, controller=simc_pi(proc), noise_std=noise, n_samples=3000,
                         disturbances=load, seed=seed)  # fmt: skip
        r = simulate_loop(cfg)
        return r.pv, r.op, r.sp

    normal = baseline_from(*run(0.1, 1), source="last month")
    pv, op, sp = run(0.1, 2)
    same = diagnose(pv, op, 1.0, sp=sp, loop_type="temperature", baseline=normal)
    assert same.cause == "ok", same.notes
    assert 0.5 < same.indices["variability_ratio"] < 2.0
    # a noisier loop whose tests find nothing wrong (a transmitter gone bad, say)
    pv, op, sp = run(0.8, 3)
    plain = diagnose(pv, op, 1.0, sp=sp, loop_type="temperature", quantify=False)
    assert plain.cause == "ok", plain.notes
    worse = diagnose(pv, op, 1.0, sp=sp, loop_type="temperature", baseline=normal, quantify=False)
    assert worse.indices["variability_ratio"] >= 3.0
    assert worse.cause != "ok", worse.notes
    assert any("x its baseline" in n and "last month" in n for n in worse.notes)
    for decide_by in ("rules", "learned"):
        d = diagnose(pv, op, 1.0, sp=sp, loop_type="temperature", baseline=normal,
                     quantify=False, params=ChainParams(decide_by=decide_by))  # fmt: skip
        assert d.cause != "ok", (decide_by, d.notes)


def test_flat_pv_while_op_moves_names_both_readings() -> None:
    """Issue 46 item 7: not a bare data_quality, but a frozen transmitter or a valve that does
    not move, with the evidence for each."""
    n = 600
    op = 40.0 + 10.0 * np.sin(np.arange(n) / 50.0)
    pv = np.full(n, 50.0)
    d = diagnose(pv, op, 1.0)
    assert d.cause == "data_quality"
    note = next(x for x in d.notes if "while PV stayed flat" in x)
    assert "transmitter" in note and "valve" in note and "100 %" in note
    assert "20.0 % of travel" in note
    # an OP that hardly moves says nothing about the valve
    still = diagnose(pv, np.full(n, 40.0) + 0.01 * np.sin(np.arange(n)), 1.0)
    assert not any("while PV stayed flat" in x for x in still.notes)


def test_spectral_evidence_reads_a_cycle_against_the_integral_time() -> None:
    """A sine of 100 samples with Ti 25 samples peaks at f·Ti 0.25 with no harmonics; a
    square wave of the same period carries a third harmonic of 1/9 of its power; white noise
    spreads its power flat (Hann-windowed periodogram's flatness about 0.56)."""
    from plantcheck.diagnosis.evidence import spectral_evidence

    k = np.arange(4000)
    sine = spectral_evidence(np.sin(2 * np.pi * k / 100), 25.0)
    assert sine["peak_f_ti"] == pytest.approx(np.log10(0.25), abs=0.01)
    assert sine["peak_share"] > 0.95 and sine["harmonic_3"] < 1e-3
    assert sine["error_band_4"] > 0.95  # 0.1-0.3 cycles per Ti
    square = spectral_evidence(np.sign(np.sin(2 * np.pi * (k + 0.5) / 100)), 25.0)
    assert square["harmonic_3"] == pytest.approx(1 / 9, rel=0.15)
    noise = spectral_evidence(np.random.default_rng(0).normal(size=4096), None)
    assert 0.45 < noise["spectral_flatness"] < 0.65 and "error_band_0" not in noise
    shares = [sine[f"error_band_{b}"] for b in range(8)]
    assert sum(shares) <= 1.0 + 1e-9


def test_correlation_evidence_reads_the_shape_and_the_order_of_error_and_op() -> None:
    """An AR(1) error of correlation time 50 samples decays exponentially (the lag below 0.5
    over the lag below 0.1: ln 2 / ln 10 = 0.30) with no undershoot; a damped cycle swings its
    ACF negative; added white noise leaves the shape (the ACF is read over lag 1's); OP that
    follows the error 20 samples later correlates with it most at that lag, whichever way the
    controller acts, and stays correlated longer when it integrates the error."""
    from scipy.signal import lfilter

    from plantcheck.diagnosis.evidence import correlation_evidence

    rng = np.random.default_rng(1)
    n, a = 200_000, np.exp(-1 / 50)
    e = lfilter([1.0], [1.0, -a], rng.normal(size=n))
    op = np.concatenate([np.zeros(20), e[:-20]])
    ev = correlation_evidence(e, op)
    assert ev["error_acf_shape"] == pytest.approx(np.log(2) / np.log(10), abs=0.05)
    assert 10 ** ev["log_error_acf_samples"] == pytest.approx(51, rel=0.15)
    assert ev["error_acf_min"] > -0.1 and ev["error_lag1"] > 0.95
    assert ev["error_op_ccf_peak"] > 0.95
    assert 10 ** ev["error_op_ccf_lag"] * 50 == pytest.approx(21, rel=0.1)
    assert ev["op_error_ccf_0"] == pytest.approx(a**20, abs=0.03)
    flipped = correlation_evidence(e, -op)
    assert flipped["op_error_ccf_0"] == pytest.approx(ev["op_error_ccf_0"], abs=1e-12)
    noisy = correlation_evidence(e + 0.5 * np.std(e) * rng.normal(size=n), op)
    assert noisy["error_acf_shape"] == pytest.approx(ev["error_acf_shape"], abs=0.05)
    assert noisy["error_lag1"] < 0.85
    integral = correlation_evidence(e, np.cumsum(e))
    assert integral["op_error_acf_ratio"] > 0.5  # OP correlated over 3x the error's time
    r = 0.98 * np.exp(2j * np.pi / 40)
    cycle = lfilter([1.0], [1.0, -2 * r.real, abs(r) ** 2], rng.normal(size=n))
    assert correlation_evidence(cycle, op)["error_acf_min"] < -0.5
    assert correlation_evidence(np.zeros(10), np.zeros(10)) == {}


def test_a_faulty_corpus_window_shows_against_its_twin_without_the_fault() -> None:
    """Corpus version 7: a window labelled stiction, sluggish or external disturbance has an
    error σ at least 1.3 times that of its twin (the same loop, loads, noise and set points
    with a linear valve, the well-tuned controller or no periodic load); a loop near its
    stability limit rings: 1.3² times its twin's error power around the ultimate frequency."""
    from plantcheck.simulator.corpus import VISIBLY_FAULTY, ringing_power

    for index in range(12):
        case, rec = draw_case(7, index)
        if case.cause in ("ok", "saturation"):
            assert case.twin is None
            continue
        assert case.twin is not None, case.cause
        twin = simulate_loop(case.twin)
        e, e_twin = rec.sp - rec.pv, twin.sp - twin.pv
        cfg, tw = case.config, case.twin
        if case.cause == "aggressive_tuning":
            ts, tu = cfg.sample_time_s, case.ultimate_period_s
            ratio = ringing_power(e, ts, tu) / ringing_power(e_twin, ts, tu)
            assert ratio >= VISIBLY_FAULTY**2, (index, ratio)
            assert abs(tw.controller.Kc) < abs(cfg.controller.Kc)
            continue
        ratio = float(np.std(e)) / float(np.std(e_twin))
        assert ratio >= VISIBLY_FAULTY, (index, case.cause, ratio)
        if case.cause == "stiction":
            assert tw.S == 0.0 and tw.valve == "linear" and cfg.S > 0.0
        elif case.cause == "external_disturbance":
            assert len(tw.disturbances) < len(cfg.disturbances)
        else:
            assert abs(tw.controller.Kc) > abs(cfg.controller.Kc)


def test_process_evidence_reads_the_controller_against_simc() -> None:
    """A controller at the SIMC setting of the model reads 0 (log10 of the ratios); twice
    its gain log10 2; a fifth of the integral time log10 0.2; θ is taken half a sample
    longer (the hold), so θ 3.5 samples is SIMC's 4 (Skogestad 2003)."""
    from plantcheck.diagnosis.evidence import process_evidence

    at = process_evidence(2.0, 20.0, 3.5, 0.9, 20.0 / (2 * 2 * 4), 20.0, False)
    assert at["kc_over_simc"] == pytest.approx(0.0, abs=1e-12)
    assert at["ti_over_simc"] == pytest.approx(0.0, abs=1e-12)
    assert at["dead_time_share"] == pytest.approx(4 / 24)
    assert at["log_dead_time_samples"] == pytest.approx(np.log10(4))
    hot = process_evidence(-2.0, 20.0, 3.5, 0.9, -2 * 20.0 / 16, 4.0, False)
    assert hot["kc_over_simc"] == pytest.approx(np.log10(2))
    assert hot["ti_over_simc"] == pytest.approx(np.log10(0.2))
    level = process_evidence(0.05, 0.0, 9.5, 0.9, 1 / (0.05 * 2 * 10), 80.0, True)
    assert level["kc_over_simc"] == pytest.approx(0.0, abs=1e-12)
    assert level["ti_over_simc"] == pytest.approx(0.0, abs=1e-12)
    assert level["dead_time_share"] is None
    blind = process_evidence(0.0, 20.0, 3.5, -0.2, 1.0, 20.0, False)
    assert "kc_over_simc" not in blind and blind["process_fit"] == -0.2
    assert set(at) <= set(FEATURES)


def test_the_error_spectrum_read_once_gives_what_each_reads_alone() -> None:
    """``shape_evidence`` and ``correlation_evidence`` handed the whole window's error
    spectrum give what each computes on its own, to the bit, and the correlation time is
    ``fft_acf``'s first lag below 1/e."""
    from plantcheck.diagnosis.evidence import _acf_time, correlation_evidence, shape_evidence
    from plantcheck.diagnosis.signal_tools import SignalSpectrum, detrend, fft_acf

    rng = np.random.default_rng(2)
    n = 3_000
    pv = 50.0 + np.cumsum(rng.normal(0.0, 0.1, n)) * 0.05 + rng.normal(0.0, 0.2, n)
    op = 40.0 + np.cumsum(rng.normal(0.0, 0.2, n)) * 0.1
    sp = np.full(n, 50.0)
    ed = detrend(sp - pv)
    error = SignalSpectrum.of(ed)
    assert shape_evidence(pv, op, sp, 2.0, 30.0, error) == shape_evidence(pv, op, sp, 2.0, 30.0)
    assert correlation_evidence(sp - pv, op, error) == correlation_evidence(sp - pv, op)
    acf = fft_acf(ed, max_lag=n)
    assert _acf_time(error) == float(np.flatnonzero(acf[1:] < 1.0 / np.e)[0] + 1)
    assert _acf_time(SignalSpectrum.of(np.zeros(50))) is None
