"""Plant-wide oscillation groups (issue 49 item 3): loops sharing a period (harmonics
considered) and coherent over the same span are one group whose source is the member that
makes the oscillation itself; an independent loop at a nearby period, and one at another
period, are in no group. Signals built here with known couplings and lags."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from plantcheck.diagnosis.plant_oscillation import (
    OscillatingLoop,
    common_period,
    own_oscillation,
    plant_oscillations,
)

TS = 1.0
N = 3600


def _lag(x: np.ndarray, tau_s: float) -> np.ndarray:
    a = np.exp(-TS / tau_s)
    return np.asarray(lfilter([1 - a], [1, -a], x))


def _plant(seed: int = 1) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(N) * TS
    cycle = np.sign(np.sin(2 * np.pi * t / 60.0))  # a sticky valve's square-ish cycle
    noise = lambda: 0.3 * rng.standard_normal(N)  # noqa: E731
    return {
        "SRC": cycle + noise(),
        # downstream: delayed 5 s and 15 s, through a 10-s and a 30-s lag, one inverted
        "D1": -_lag(np.roll(cycle, 5), 10.0) + noise(),
        "D2": 3 * _lag(np.roll(cycle, 15), 30.0) + noise(),
        "NEAR": np.sin(2 * np.pi * t / 58.0) + noise(),  # independent, 3 % off the period
        "FAR": np.sin(2 * np.pi * t / 150.0) + noise(),
    }


def _members(own_src: str = "its valve (cause stiction)") -> list[OscillatingLoop]:
    s = _plant()
    periods = {"SRC": (60.0, 20.0), "D1": (60.5,), "D2": (59.0,), "NEAR": (58.0,), "FAR": (150.0,)}
    return [
        OscillatingLoop(name, periods[name], x, own_src if name == "SRC" else "")
        for name, x in s.items()
    ]


def test_one_group_with_its_source_and_lags() -> None:
    groups = plant_oscillations(_members(), TS)
    assert len(groups) == 1
    g = groups[0]
    assert g.loops == ("D1", "D2", "SRC") and g.source == "SRC"
    assert g.period_s == pytest.approx(60.0, abs=1.0)
    # true lags: 5 s + the 10-s lag's phase at 60 s (7.7 s), 15 s + the 30-s lag's (12 s)
    assert g.lags_s["D1"] == pytest.approx(12.7, abs=2.0)
    assert g.lags_s["D2"] == pytest.approx(27.0, abs=2.0)
    assert g.evidence[0].startswith("SRC: its valve")


def test_without_a_member_that_makes_it_the_source_is_outside() -> None:
    groups = plant_oscillations(_members(own_src=""), TS)
    assert [g.loops for g in groups] == [("D1", "D2", "SRC")]
    assert groups[0].source is None and "look upstream" in groups[0].evidence[0]


def test_a_valve_outranks_a_loop_that_cycles_by_its_tuning() -> None:
    m = _members()
    m[1] = OscillatingLoop("D1", m[1].periods_s, m[1].signal, "its own tuning", 1)
    assert plant_oscillations(m, TS)[0].source == "SRC"


def test_harmonics_and_periods_apart() -> None:
    assert common_period((60.0,), (30.5,)) == 60.0  # the 2nd harmonic
    assert common_period((20.2,), (60.0,)) == 60.0  # the 3rd
    assert common_period((60.0,), (15.0,)) is None  # the 4th: beyond `harmonics`
    assert common_period((60.0,), (70.0,)) is None
    assert common_period((100.0, 60.0), (61.0,)) == 60.0  # any of a loop's periods


def test_a_short_shared_span_groups_nothing() -> None:
    m = [OscillatingLoop(x.loop, x.periods_s, x.signal[:500], x.own) for x in _members()]
    assert plant_oscillations(m, TS) == []  # 500 s hold 8 cycles of 60 s: too few


def test_own_oscillation_from_a_diagnosis() -> None:
    assert own_oscillation({"cause": "stiction", "stiction": {"S": 4.04}}) == (
        "its valve (cause stiction, S 4.04 %)",
        0,
    )
    assert own_oscillation({"cause": "aggressive_tuning"})[1] == 1
    assert own_oscillation({"cause": "external_disturbance"}) == ("", 0)
