"""Vectorised valve models (diagnosis.valve_models) against hand-worked sequences, the
step-wise simulator valves, and the grid against the single-pair functions."""

from __future__ import annotations

import numpy as np
import pytest

from plantcheck.diagnosis.valve_models import (
    SCALAR_PAIRS,
    choudhury,
    choudhury_grid,
    he,
    he_grid,
    kano,
    kano_grid,
    stenman,
    stenman_grid,
)
from plantcheck.simulator.valves import HeValve, KanoValve

RNG = np.random.default_rng(0)
U = 50 + np.cumsum(RNG.normal(0, 0.3, 3000)) + 5 * np.sin(np.arange(3000) / 50)


def test_kano_hand_worked_reversal() -> None:
    # S = 4, J = 2: ramp 50 -> 60 (0.5 steps), reverse to 50
    u = np.concatenate([np.arange(50, 60.01, 0.5), np.arange(59.5, 49.99, -0.5)])
    v = kano(u, 4.0, 2.0)
    i60 = int(np.argmax(u))
    assert v[i60] == pytest.approx(59.0)  # moving up, lagging by (S - J)/2 = 1
    # after the reversal: stuck while the input comes back by no more than S = 4
    back = u[i60:] >= 56.0
    assert np.all(v[i60:][back] == pytest.approx(59.0))
    first = i60 + int(np.argmax(~back))
    assert u[first] == pytest.approx(55.5)
    assert v[first] == pytest.approx(56.5)  # u + (S - J)/2: a jump of 2.5 (J + 0.5 overshoot)


def test_choudhury_equals_kano_and_grid_equals_single() -> None:
    # more pairs than SCALAR_PAIRS: the grid steps all pairs at once, kano() loops per sample
    S = np.array([0.5, 2.0, 4.0, 4.0, 3.0, 1.0, 6.0, 2.5])
    J = np.array([0.0, 1.0, 2.0, 4.0, 3.6, 0.2, 1.0, 2.5])
    assert S.size > SCALAR_PAIRS
    grid_k = kano_grid(U, S, J)
    grid_c = choudhury_grid(U, S, J)
    for i in range(S.size):
        assert np.array_equal(grid_k[i], kano(U, S[i], J[i]))
        assert np.allclose(grid_c[i], choudhury(U, S[i], J[i]))
        assert np.allclose(grid_c[i], grid_k[i])  # methods §5.2: identical outputs


def test_kano_start_band() -> None:
    # S = J = 5 and an input swinging ±4 around its first sample: BDSIM's start (stuck at
    # u0, free outside [u0 − J, u0 + S]) never moves; stuck at u0 − S (free outside
    # [u0 − S − J, u0]) the valve breaks free as the input first rises past u0, then sticks
    # at each reversal and slips by J + overshoot once the input comes back by S
    u = 50 + 4 * np.sin(np.arange(400) * 2 * np.pi / 100)
    assert np.all(kano(u, 5.0, 5.0) == 50.0)
    v = kano(u, 5.0, 5.0, stuck=45.0)
    assert v[1] == pytest.approx(u[1])  # moving up with the input, (S − J)/2 = 0 behind
    assert v[25] == pytest.approx(54.0)  # stuck at the first peak
    slips = np.flatnonzero(np.diff(v[30:]) != 0)
    assert u[30 + slips[0] + 1] < 49.0 + 1e-9  # came back by more than S = 5 from 54
    # the grid with start bands equals the single pair, row by row
    S = np.array([0.5, 2.0, 4.0, 4.0, 3.0, 1.0, 6.0, 2.5])
    J = np.array([0.0, 1.0, 2.0, 4.0, 3.6, 0.2, 1.0, 2.5])
    stuck = U[0] - S + np.linspace(0.0, 1.0, S.size) * (S + J)
    grid = kano_grid(U, S, J, stuck=stuck)
    for i in range(S.size):
        assert np.array_equal(grid[i], kano(U, S[i], J[i], stuck=stuck[i]))
    assert np.array_equal(kano_grid(U, S, J, stuck=np.full(S.size, U[0])), kano_grid(U, S, J))


@pytest.mark.parametrize(("S", "J"), [(4.0, 2.0), (3.0, 0.0), (4.0, 4.0), (2.0, 3.0)])
def test_grid_models_match_step_wise_simulator(S: float, J: float) -> None:
    kv = KanoValve(S, J)
    assert np.array_equal(kano(U, S, J, clip=True), [kv.step(x) for x in U])
    hv = HeValve((S + J) / 2, max((S - J) / 2, 0.0))
    assert np.allclose(he(U, (S + J) / 2, max((S - J) / 2, 0.0)), [hv.step(x) for x in U])


def test_he_saw_tooth_on_slow_ramp() -> None:
    u = np.arange(50.0, 70.0, 0.01)
    v = he_grid(u, [3.0], [1.0])[0]
    jumps = np.abs(np.diff(v))
    assert np.allclose(jumps[jumps > 1e-9], 2.0, atol=0.02)


def test_he_remembers_where_it_started() -> None:
    # f_s = 3, f_d = 1: on a ramp the valve slips by 2 whenever the input leads it by 3, so a
    # valve that started 1 lower keeps slipping earlier for the whole ramp (a phase shift)
    u = np.arange(50.0, 70.0, 0.01)
    a = he(u, 3.0, 1.0)
    b = he(u, 3.0, 1.0, x0=49.0)
    assert np.flatnonzero(np.diff(b) > 0)[0] < np.flatnonzero(np.diff(a) > 0)[0]
    assert np.abs(a - b)[-500:].min() > 0.5
    # a pure deadband (f_s = f_d) forgets its start once the input has crossed the band
    c, d = he(u, 2.0, 2.0), he(u, 2.0, 2.0, x0=48.5)
    assert np.array_equal(c[500:], d[500:])


def test_he_grid_equals_single_with_starts() -> None:
    fs = np.linspace(0.5, 4.0, SCALAR_PAIRS + 3)
    fd = 0.4 * fs
    x0 = U[0] + np.linspace(-2.0, 2.0, fs.size)
    grid = he_grid(U, fs, fd, x0=x0)
    for i in range(fs.size):
        assert np.array_equal(grid[i], he(U, fs[i], fd[i], x0=x0[i]))


def test_stenman_stick_band() -> None:
    u = np.array([50.0, 50.5, 50.9, 51.2, 51.0, 49.9, 49.7])
    assert stenman(u, 1.0).tolist() == [50.0, 50.0, 50.0, 51.2, 51.2, 49.9, 49.9]
    assert stenman_grid(u, [0.0, 1.0]).shape == (2, 7)


def test_he_rejects_a_negative_kinetic_band() -> None:
    with pytest.raises(ValueError, match="f_d must be >= 0"):
        he_grid(np.linspace(0.0, 10.0, 50), [2.0] * 8, [-0.5] * 8)


@pytest.mark.parametrize("name", ["kano", "he", "choudhury", "backlash"])
def test_drifting_friction_changes_the_band_at_each_stop_and_only_then(name: str) -> None:
    """Spread 0 is the plain model sample for sample; a spread moves the bands by one common
    factor at each stop (J stays at most S), the same for the same seed."""
    from dataclasses import replace

    from plantcheck.simulator.loop import LoopConfig, make_valve
    from plantcheck.simulator.valves import FRICTION_FIELDS, DriftingFriction

    cfg = LoopConfig(valve=name, S=3.0, J=1.0, seed=4)  # type: ignore[arg-type]
    plain, same = make_valve(cfg), make_valve(replace(cfg, friction_spread=0.0))
    assert [plain.step(u) for u in U] == [same.step(u) for u in U]
    drifting = make_valve(replace(cfg, friction_spread=0.3))
    again = make_valve(replace(cfg, friction_spread=0.3))
    assert isinstance(drifting, DriftingFriction)
    fields = FRICTION_FIELDS[type(drifting.valve)]
    bands, out = set(), []
    for u in U:
        out.append(drifting.step(u))
        bands.add(tuple(getattr(drifting.valve, k) for k in fields))
    assert out == [again.step(u) for u in U]
    assert len(bands) > 10
    first = tuple(getattr(make_valve(cfg), k) for k in fields)
    ratios = {round(b[i] / first[i], 9) for b in bands for i in range(len(fields)) if first[i]}
    assert len(ratios) == len(bands)  # one factor for every field of a stop
