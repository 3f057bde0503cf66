"""A retuning inside the window (issue 48): found to the sample on the bundled plant's loops,
the window judged from it on; one controller throughout, a manual stretch or a clamp never
cut a window."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime

import numpy as np
import pytest
from numpy.typing import NDArray

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.controller_change import (
    ControllerChangeParams,
    find_controller_change,
    latest_controller_change,
)
from plantcheck.simulator.corpus import draw_case
from plantcheck.simulator.loop import simulate_loop, simulate_retuned_loop
from plantcheck.simulator.plant import Plant
from plantcheck.simulator.scenario import LoopSpec, Scenario, load_scenario

N = 3600
"""Samples per window (1 s each): the demo's hour."""


def _run(sc: Scenario, n: int) -> NDArray[np.float64]:
    """(n, loops, SP/PV/OP/MV/Mode) of the scenario's plant after its 30-min warm-up."""
    plant = Plant(sc, datetime(2026, 1, 1, tzinfo=UTC))
    out = np.empty((n, len(plant.loops), 5))
    for k in range(n + 1800):
        plant.step()
        if k >= 1800:
            out[k - 1800] = plant.values
    return out


def _with(sc: Scenario, loop: str, **update: object) -> Scenario:
    loops = [s.model_copy(update=update) if s.id == loop else s for s in sc.loop]
    return sc.model_copy(update={"loop": loops})


def _span(spec: LoopSpec) -> float:
    return spec.range[1] - spec.range[0]


@pytest.mark.parametrize(("loop", "kc", "ti"), [("PIC301", 1.1, 10.0), ("TIC401", 0.9, 30.0)])
def test_a_retuning_is_found_to_the_sample_and_judged_alone(
    loop: str, kc: float, ti: float
) -> None:
    sc = load_scenario(None)
    at = 1800 + 2000  # simulated s: 2,000 samples into the window
    sc = _with(sc, loop, controller_schedule=[(float(at), kc, ti)])
    spec = next(s for s in sc.loop if s.id == loop)
    i = [s.id for s in sc.loop].index(loop)
    w = _run(sc, N)[:, i]
    change = find_controller_change(w[:, 1], w[:, 2], w[:, 0], 1.0)
    assert change is not None
    assert abs(change.at - 2000) <= 2, change
    s = change.sides
    # the simulator's Kc is in % of OP per % of span; the diagnosis's per PV unit
    before = spec.controller.Kc * 100.0 / _span(spec)
    assert s.kc_before == pytest.approx(before, rel=0.1)  # Tustin midpoint: Kc(1 - ts/2Ti)
    assert s.kc_after == pytest.approx(kc * 100.0 / _span(spec), rel=0.1)
    assert s.ti_before_s == pytest.approx(spec.controller.Ti_s, rel=0.1)
    assert s.ti_after_s == pytest.approx(ti, rel=0.1)
    assert min(s.fit_before, s.fit_after) >= 0.9
    d = diagnose(w[:, 1], w[:, 2], 1.0, sp=w[:, 0], loop_type=spec.type, quantify=False)
    assert d.samples == N - change.at
    assert d.controller_change is not None and d.to_dict()["controller_change"][
        "at_s"
    ] == pytest.approx(change.at, abs=0.5)
    assert d.notes[0].startswith("the controller was retuned 2000 s into the window"), d.notes


def test_the_last_of_two_retunings_is_the_one_judged_from() -> None:
    sc = _with(
        load_scenario(None), "PIC301", controller_schedule=[(2800.0, 2.0, 9.0), (4300.0, 1.0, 12.0)]
    )
    i = [s.id for s in sc.loop].index("PIC301")
    w = _run(sc, N)[:, i]
    change = latest_controller_change(w[:, 1], w[:, 2], w[:, 0], 1.0)
    assert change is not None and abs(change.at - 2500) <= 2, change


def test_one_controller_throughout_is_never_cut() -> None:
    """Every loop of the bundled plant as it is (sticky valves, a clamp, a positioner fault,
    loads from outside, set-point steps) and one with a manual stretch."""
    sc = load_scenario(None)
    sc = _with(sc, "FIC101", manual=[(2500.0, 3300.0)])
    w = _run(sc, N)
    for i, spec in enumerate(sc.loop):
        auto = w[:, i, 4] > 0.5
        found = find_controller_change(w[:, i, 1], w[:, i, 2], w[:, i, 0], 1.0, auto)
        assert found is None, (spec.id, found)
        # without the mode: the manual stretch's OP is no PI of the error
        assert find_controller_change(w[:, i, 1], w[:, i, 2], w[:, i, 0], 1.0) is None, spec.id


@pytest.mark.parametrize("index", [483, 691])
def test_a_historians_recording_error_is_no_retuning(index: int) -> None:
    """Corpus loops recorded by a historian (483: compressed, 691: quantised), each with a
    set-point move after a quiet stretch: the recording error biases the quiet side's
    settings (errors in variables), and the search once read a retuning there. The rows
    averaged over ``confirm_block`` samples do not confirm it; the same loop retuned at its
    middle (Kc halved) is still found to the sample. Both windows drew a short manual or
    frozen stretch in corpus version 11: the loop is read without it, as version 10 drew it."""
    case, _ = draw_case(202, index)
    cfg = replace(case.config, manual=(), frozen_pv=())
    rec = simulate_loop(cfg)
    ts, c = cfg.sample_time_s, cfg.controller
    assert case.family["recording"] in ("compressed", "quantised")
    assert latest_controller_change(rec.pv, rec.op, rec.sp, ts) is None
    unconfirmed = ControllerChangeParams(confirm_block=1)
    assert latest_controller_change(rec.pv, rec.op, rec.sp, ts, params=unconfirmed) is not None
    made = cfg.n_samples // 2
    retuned = simulate_retuned_loop(cfg, made, c.Kc * 0.5, c.Ti_s)
    change = latest_controller_change(retuned.pv, retuned.op, retuned.sp, ts)
    assert change is not None and abs(change.at - made) <= 2, change


def test_short_or_empty_windows_are_left_whole() -> None:
    nan = np.full(2000, np.nan)
    ramp = np.linspace(0.0, 1.0, 2000)
    assert find_controller_change(nan, nan, None, 1.0) is None
    assert find_controller_change(ramp[:300], ramp[:300], None, 1.0) is None


def test_a_frozen_transmitter_under_a_fixed_set_point_is_diagnosed_not_an_error() -> None:
    """PV repeating one value and a fixed set point: the control error is constant, every
    split's normal matrix singular, which once stopped the diagnosis with LinAlgError before
    the window checks could say what the flat PV may be (issue 46 item 7)."""
    n = 3600
    op = 50.0 + np.cumsum(np.random.default_rng(0).normal(size=n)) * 0.05
    pv, sp = np.full(n, 42.0), np.full(n, 45.0)
    assert find_controller_change(pv, op, sp, 1.0) is None
    d = diagnose(pv, op, 1.0, sp=sp, loop_type="flow", quantify=False)
    assert d.cause == "data_quality"
    assert any("transmitter is frozen" in note for note in d.notes), d.notes
