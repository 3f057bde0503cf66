"""Simulator dynamics against theory: exact step responses, a sticky valve's limit cycle, the
oscillation period at the ultimate gain; and the on-line plant against the batch model."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from simhelpers import START

from plantcheck.diagnosis import detect_oscillation
from plantcheck.simulator.batch_loop import simulate_loops
from plantcheck.simulator.cases import ultimate_gain
from plantcheck.simulator.loop import (
    ClosedLoop,
    Disturbance,
    LoopConfig,
    PIController,
    Process,
    loop_inputs,
    manual_mask,
    simulate_loop,
    simulate_retuned_loop,
)
from plantcheck.simulator.plant import Plant
from plantcheck.simulator.scenario import Scenario, load_scenario, parse_scenario


def _open_loop_step(process: Process, du: float, n: int, ts: float) -> np.ndarray:
    """PV after an OP step of ``du`` at k = 0, controller in manual (OP held)."""
    loop = ClosedLoop(LoopConfig(process=process, sample_time_s=ts, sp=50.0, u0=50.0))
    loop.auto = False
    loop.integral = 50.0 + du
    return np.array([loop.step(50.0)[0] for _ in range(n)])


def _served(sc: Scenario, n: int) -> np.ndarray:
    """The first loop's served (SP, PV, OP, MV, Mode) over ``n`` steps of the plant."""
    plant = Plant(sc, START)
    rows = []
    for _ in range(n):
        plant.step()
        rows.append(plant.values[0].copy())
    return np.array(rows)


@pytest.mark.parametrize(("tau", "theta", "ts"), [(10.0, 3.0, 1.0), (5.0, 0.0, 0.5)])
def test_first_order_step_response_is_exact(tau: float, theta: float, ts: float) -> None:
    K, du, n = 2.0, 5.0, 200
    pv = _open_loop_step(Process("fopdt", K=K, tau_s=tau, theta_s=theta), du, n, ts)
    t = np.arange(n) * ts  # the valve moves at t = 0; pv[k] is measured at t = k·ts
    expected = 50.0 + K * du * (1.0 - np.exp(-np.clip(t - theta, 0.0, None) / tau))
    np.testing.assert_allclose(pv, expected, atol=1e-9)


def test_integrating_step_response_is_a_ramp() -> None:
    K, du, ts, theta = 0.1, 4.0, 1.0, 2.0
    pv = _open_loop_step(Process("integrating", K=K, theta_s=theta), du, 100, ts)
    t = np.arange(100) * ts
    expected = 50.0 + K * du * np.clip(t - theta, 0.0, None)
    np.testing.assert_allclose(pv, expected, atol=1e-9)


def test_sticky_valve_produces_its_limit_cycle() -> None:
    sc = load_scenario()
    v = _served(sc.model_copy(update={"loop": [s for s in sc.loop if s.id == "FIC102"]}), 3600)
    pv, op = v[:, 1], v[:, 2]
    osc = detect_oscillation(pv[600:], 1.0)
    assert osc.oscillating and osc.regularity is not None and osc.regularity > 3
    # stick-slip: the valve moves in jumps, OP ramps between them (a triangle wave of amplitude
    # about S/2 around its mean)
    assert 1.0 < np.ptp(op[600:]) < 6.0


def _cycles(kc: float, proc: Process, ti: float, ts: float) -> tuple[float, float]:
    """Mean period (s) and amplitude ratio last/first cycles after a set-point bump."""
    loop = ClosedLoop(
        LoopConfig(process=proc, controller=PIController(Kc=kc, Ti_s=ti), sample_time_s=ts)
    )
    pv = np.array([loop.step(50.0 if k < 10 else 51.0)[0] for k in range(3000)])
    x = pv[200:] - 51.0
    ups = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    period = float(np.mean(np.diff(ups))) * ts
    return period, float(np.ptp(x[ups[8] : ups[10]]) / np.ptp(x[ups[1] : ups[3]]))


def test_marginal_gain_oscillates_at_the_ultimate_period() -> None:
    proc = Process("fopdt", K=1.5, tau_s=8.0, theta_s=2.0)
    ts, ti = 0.1, 8.0
    ku, tu = ultimate_gain(proc, ti, ts)
    period, _ = _cycles(ku, proc, ti, ts)
    assert period == pytest.approx(tu, rel=0.03)
    # the ultimate gain separates dying from growing oscillations
    assert _cycles(0.95 * ku, proc, ti, ts)[1] < 0.9
    assert _cycles(1.05 * ku, proc, ti, ts)[1] > 1.1


def test_manual_mode_holds_op_and_serves_mode_zero() -> None:
    sc = parse_scenario(
        '[[loop]]\nid = "A"\nmanual = [[10.0, 20.0]]\nnoise_std = 0.5\n'
        'disturbances = [{ where = "load", random_walk_std = 0.5 }]\n'
    )
    v = _served(sc, 30)
    assert np.all(v[10:20, 4] == 0.0) and np.all(v[:10, 4] == 1.0) and np.all(v[20:, 4] == 1.0)
    assert np.ptp(v[10:20, 2]) == 0.0  # OP frozen in manual
    assert np.ptp(v[20:, 2]) > 0.0
    assert np.all(np.isnan(v[:, 3]))  # no positioner feedback served


def test_engineering_units_and_set_point_schedule() -> None:
    sc = parse_scenario(
        '[[loop]]\nid = "T"\nrange = [100.0, 300.0]\nunit = "degC"\n'
        "sp_schedule = [[5.0, 60.0]]\nsp_repeat_s = 10.0\n"
    )
    sps = _served(sc, 20)[:, 0]
    assert sps[0] == 200.0 and sps[5] == 220.0 and sps[10] == 200.0 and sps[15] == 220.0


def test_a_loop_carries_another_loops_cycle_downstream() -> None:
    """``from_loop``: B's load is A's PV deviation from its set point times ``gain``,
    ``delay_s`` later; A is untouched by B (issue 49 item 3: a plant-wide oscillation)."""
    sc = parse_scenario(
        '[[loop]]\nid = "A"\nsp_schedule = [[10.0, 60.0]]\n'
        'process = { kind = "fopdt", K = 1.0, tau_s = 5.0, theta_s = 1.0 }\n'
        "controller = { Kc = 0.5, Ti_s = 5.0 }\n\n"
        '[[loop]]\nid = "B"\ncontroller = { Kc = 0.01, Ti_s = 1000.0 }\n'
        'process = { kind = "fopdt", K = 1.0, tau_s = 1.0, theta_s = 0.0 }\n'
        'disturbances = [{ where = "load", from_loop = "A", gain = -2.0, delay_s = 3.0 }]\n'
    )
    plant = Plant(sc, START)
    rows = []
    for _ in range(40):
        plant.step()
        rows.append(plant.values.copy())
    v = np.array(rows)
    dev_a = v[:, 0, 1] - v[:, 0, 0]  # A's PV − SP, % (range 0-100)
    assert dev_a[12] < -5.0  # the set-point step: A's PV trails its new set point
    # B barely controls: its PV follows its load, −2 × A's deviation 3 s before, through a
    # 1-s lag; before A moved, B sits at its set point
    assert abs(v[11, 1, 1] - 50.0) < 0.5
    load = -2.0 * dev_a
    assert v[25, 1, 1] - 50.0 == pytest.approx(load[21], rel=0.3)


def test_a_loop_stepped_sample_by_sample_records_what_the_batch_run_does() -> None:
    """``ClosedLoop.step`` (the live plant) and ``simulate_loop`` (records, the corpus) are one
    model: a sticky valve with drifting friction on a second-order process with a zero and
    dead time, a PV filter, an output limit and noise give the same samples to the last bit."""
    from plantcheck.simulator.loop import simulate_loop

    cfg = LoopConfig(
        process=Process("fopdt", K=1.5, tau_s=20.0, tau2_s=6.0, zero_s=-3.0, theta_s=4.0),
        controller=PIController(Kc=0.6, Ti_s=22.0, op_max=58.0),
        valve="kano", S=3.0, J=1.0, friction_spread=0.2, noise_std=0.1, pv_filter_s=2.0,
        sp_steps=((150.0, 53.0),), n_samples=400, warmup_samples=0, seed=5,
    )  # fmt: skip
    rec = simulate_loop(cfg)
    rng = np.random.default_rng(cfg.seed)
    noise = rng.normal(0.0, cfg.noise_std, cfg.n_samples)
    loop = ClosedLoop(cfg)
    sp = np.where(np.arange(cfg.n_samples) * cfg.sample_time_s >= 150.0, 53.0, 50.0)
    stepped = np.array(
        [loop.step(float(s), 0.0, 0.0, float(v)) for s, v in zip(sp, noise, strict=True)]
    )
    np.testing.assert_array_equal(stepped[:, 0], rec.pv)
    np.testing.assert_array_equal(stepped[:, 1], rec.op)
    np.testing.assert_array_equal(stepped[:, 2], rec.mv)


@pytest.mark.parametrize(
    ("characteristic", "more_op"),
    [("linear", 0), ("equal_percentage", -1), ("quick_opening", 1)],
)
def test_a_valve_characteristic_changes_the_gain_away_from_the_operating_point(
    characteristic: str, more_op: int
) -> None:
    """Slope 1 at ``u0``, so the loop is the linear one there; above it an equal-percentage
    valve gives more flow per % of travel (a set-point rise needs less OP than through a linear
    valve) and a quick-opening valve less (it needs more)."""
    from plantcheck.simulator.loop import simulate_loop

    base = LoopConfig(
        process=Process("fopdt", K=1.0, tau_s=10.0, theta_s=1.0),
        controller=PIController(Kc=0.5, Ti_s=10.0),
        sp_steps=((20.0, 70.0),), u0=40.0, n_samples=300, warmup_samples=0,
    )  # fmt: skip
    linear = simulate_loop(base)
    rec = simulate_loop(replace(base, characteristic=characteristic, rangeability=30.0))  # type: ignore[arg-type]
    assert rec.pv[10] == pytest.approx(50.0, abs=1e-9)  # at u0 the characteristic is neutral
    assert rec.pv[-1] == pytest.approx(70.0, abs=0.05)  # the controller still gets there
    np.testing.assert_array_equal(rec.mv, rec.op)  # MV is the stem, not the flow
    assert np.sign(round(rec.op[-1] - linear.op[-1], 3)) == more_op


@pytest.mark.parametrize("shape", ["square", "triangle"])
def test_a_periodic_load_can_be_another_loops_limit_cycle(shape: str) -> None:
    """A square wave high for ``duty`` of each period, or a triangle rising for it: peak to
    peak twice the amplitude, about zero mean, its edges through ``edge_lag_s``."""
    wave = Disturbance(sine_amplitude=2.0, sine_period_s=100.0, shape=shape, duty=0.3)  # type: ignore[arg-type]
    cfg = LoopConfig(disturbances=(wave,), n_samples=2000, warmup_samples=0)
    load = loop_inputs(cfg)[3]
    assert np.ptp(load) == pytest.approx(4.0, abs=0.1)  # a triangle's tip falls between samples
    assert abs(float(np.mean(load))) < 0.05
    rising = np.diff(load) > 0 if shape == "triangle" else load[1:] > np.mean(load)
    assert float(np.mean(rising)) == pytest.approx(0.3, abs=0.015)
    lagged = loop_inputs(replace(cfg, disturbances=(replace(wave, edge_lag_s=5.0),)))[3]
    assert np.ptp(lagged) < np.ptp(load)
    if shape == "square":
        # five samples after a rising edge, 1 - 1/e of the jump is covered
        edge = int(np.flatnonzero(np.diff(load) > 0)[1]) + 1
        covered = (lagged[edge + 4] - lagged[edge - 1]) / 4.0
        assert covered == pytest.approx(1.0 - np.exp(-1.0), abs=0.02)


def test_a_limit_cycle_asks_for_a_share_of_a_period() -> None:
    with pytest.raises(ValueError, match="duty"):
        Disturbance(shape="square", duty=1.0)
    with pytest.raises(ValueError, match="edge_lag_s"):
        Disturbance(shape="square", edge_lag_s=-1.0)


def _stretched(**stretches: tuple[tuple[float, float], ...]) -> LoopConfig:
    """A noisy loop under a random-walk load, sampled at 2 s, with ``stretches``."""
    load = Disturbance(random_walk_std=0.3, steps=((300.0, 5.0),))
    return LoopConfig(
        process=Process(K=1.5, tau_s=40.0, theta_s=4.0),
        controller=PIController(Kc=0.6, Ti_s=40.0),
        disturbances=(load,),
        noise_std=0.2,
        sample_time_s=2.0,
        n_samples=600,
        warmup_samples=50,
        seed=7,
        **stretches,  # type: ignore[arg-type]
    )


def test_an_operator_holds_op_in_a_manual_stretch_and_the_load_moves_pv() -> None:
    """Manual from 200 s to 500 s of the record: OP holds its last value for those 150
    samples while the load step at 300 s moves PV away; the controller takes over after."""
    cfg = _stretched(manual=((200.0, 500.0),))
    rec = simulate_loop(cfg)
    mask = manual_mask(cfg)
    assert mask.size == rec.pv.size and int(mask.sum()) == 150
    assert np.flatnonzero(mask)[[0, -1]].tolist() == [100, 249]
    assert np.ptp(rec.op[100:250]) == 0.0 and rec.op[100] == rec.op[99]
    assert np.ptp(rec.op[250:260]) > 0.0  # back in automatic
    auto = simulate_loop(replace(cfg, manual=()))
    # in automatic the controller holds PV near its set point; in manual the load drifts it
    assert np.std(rec.pv[150:250] - 50.0) > 2.0 * np.std(auto.pv[150:250] - 50.0)
    assert np.array_equal(rec.pv[:100], auto.pv[:100])  # the same run before the stretch


def test_a_frozen_transmitter_holds_its_last_reading_and_the_controller_ramps_op() -> None:
    cfg = _stretched(frozen_pv=((100.0, 300.0),))
    rec = simulate_loop(cfg)
    assert np.ptp(rec.pv[50:150]) == 0.0 and rec.pv[50] == rec.pv[49]
    # a constant error: the integral action moves OP by the same amount every sample
    assert np.ptp(np.diff(rec.op[51:150])) < 1e-9 and abs(rec.op[149] - rec.op[50]) > 0.0
    assert np.ptp(rec.pv[150:160]) > 0.0  # live again


def test_a_loop_with_stretches_is_the_same_alone_or_among_others() -> None:
    plain = _stretched()
    cfgs = [plain, _stretched(manual=((200.0, 500.0),)), replace(plain, seed=8)]
    for alone, batched in zip((simulate_loop(c) for c in cfgs), simulate_loops(cfgs), strict=True):
        assert np.array_equal(alone.pv, batched.pv) and np.array_equal(alone.op, batched.op)


@pytest.mark.parametrize("field", ["manual", "frozen_pv"])
def test_a_stretch_must_start_before_it_ends_and_after_the_last(field: str) -> None:
    for bad in (((50.0, 10.0),), ((-1.0, 10.0),), ((0.0, 100.0), (50.0, 200.0))):
        with pytest.raises(ValueError, match=field):
            _stretched(**{field: bad})
    with pytest.raises(ValueError, match="simulate_loop"):
        simulate_retuned_loop(_stretched(**{field: ((0.0, 10.0),)}), 10, 1.0, 10.0)
