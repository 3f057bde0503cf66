"""Valve models against hand-worked sequences (methods.md §5.3, §5.4)."""

from __future__ import annotations

import numpy as np

from plantcheck.simulator.valves import HeValve, KanoValve, LinearValve


def drive(valve: KanoValve | HeValve | LinearValve, u: np.ndarray) -> np.ndarray:
    return np.array([valve.step(float(x)) for x in u])


def test_linear_valve_follows_and_clips() -> None:
    out = drive(LinearValve(), np.array([-5.0, 10.0, 50.0, 120.0]))
    assert out.tolist() == [0.0, 10.0, 50.0, 100.0]


def test_kano_reversal_needs_S_and_jumps_J() -> None:
    # S = 4, J = 2: ramp up 50 -> 60 in 0.01 steps, then down to 40.
    up = np.arange(50.0, 60.0 + 1e-9, 0.01)
    down = np.arange(60.0, 40.0 - 1e-9, -0.01)[1:]
    u = np.concatenate([up, down])
    mv = drive(KanoValve(S=4.0, J=2.0), u)
    # while moving up the stem lags the input by (S - J)/2 = 1
    k = np.searchsorted(up, 58.0)
    assert abs(mv[k] - (up[k] - 1.0)) < 1e-9
    # after the reversal at 60 the stem stays put until the input has come back by S
    rev = up.size
    stuck_until = rev + int(np.argmax(np.abs(np.diff(mv[rev - 1 :])) > 1e-9))
    assert abs(u[stuck_until] - (60.0 - 4.0)) < 0.02
    # and the first move is a slip jump of J
    jump = abs(mv[stuck_until] - mv[stuck_until - 1])
    assert abs(jump - 2.0) < 0.05
    # then it follows the input with the offset (S - J)/2 on the other side
    assert abs(mv[-1] - (u[-1] + 1.0)) < 1e-9


def test_kano_pure_deadband_has_no_jump() -> None:
    u = np.concatenate([np.linspace(50, 60, 1001), np.linspace(60, 50, 1001)[1:]])
    mv = drive(KanoValve(S=3.0, J=0.0), u)
    # after the start-up breakaway it moves continuously, the reversal included: no jump
    assert np.max(np.abs(np.diff(mv[600:]))) < 0.02


def test_he_valve_saw_tooth_on_a_slow_ramp() -> None:
    # fs = 3, fd = 1 (S = 4, J = 2): on a slow monotonic ramp the He model sticks and slips,
    # jumping by fs - fd = 2 every 2 % of input travel (Choudhury/Kano keep moving instead).
    u = np.arange(50.0, 70.0, 0.01)
    mv = drive(HeValve(fs=3.0, fd=1.0), u)
    moves = np.abs(np.diff(mv))
    jumps = moves[moves > 1e-9]
    assert jumps.size >= 6
    assert np.allclose(jumps, 2.0, atol=0.02)
    kano = drive(KanoValve(S=4.0, J=2.0), u)
    assert np.sum(np.abs(np.diff(kano)) > 0.5) <= 1  # one breakaway, then smooth motion


def test_choudhury_sticks_both_ways_for_S_then_slips_J() -> None:
    """Choudhury et al. (2005): a stopped valve needs S either way; it then jumps to
    (S - J)/2 behind the input."""
    from plantcheck.simulator.valves import ChoudhuryValve

    up = np.arange(50.0, 60.0 + 1e-9, 0.01)
    down = np.arange(60.0, 40.0 - 1e-9, -0.01)[1:]
    valve = ChoudhuryValve(S=4.0, J=2.0)
    mv = np.array([valve.step(float(x)) for x in np.concatenate([up, down])])
    # stuck at the start until the input has moved S = 4, then 1 behind it
    first = int(np.argmax(np.abs(np.diff(mv)) > 1e-9)) + 1
    assert abs(up[first] - 50.0 - 4.0) < 0.011
    assert abs(mv[first] - (up[first] - 1.0)) < 1e-9
    # after the reversal at 60 it holds until the input is S below where it stuck
    rev = up.size
    moved = rev + int(np.argmax(np.abs(np.diff(mv[rev - 1 :])) > 1e-9))
    assert abs(down[moved - rev] - 56.0) < 0.011


def test_backlash_holds_inside_its_band_and_never_slips() -> None:
    from plantcheck.simulator.valves import BacklashValve

    v = BacklashValve(d=2.0)
    out = [v.step(x) for x in (50.0, 52.0, 51.5, 50.5, 49.0, 49.0)]
    assert out == [50.0, 51.0, 51.0, 51.0, 50.0, 50.0]
