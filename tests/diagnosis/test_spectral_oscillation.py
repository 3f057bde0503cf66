"""The oscillation test with its spectral stage (Thornhill, Huang & Zhang 2003; issue 26):
irregular, multiple and slow oscillations found, noise left alone, and the real ISDB floor."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from plantcheck.diagnosis.oscillation import SPECTRAL, detect_oscillation

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "isdb-oscillation-dev"


def _drifting(n: int, period: float, seed: int) -> np.ndarray:
    """An oscillation whose period wanders by ±12 % and whose amplitude breathes, with noise
    and a slow drift: what real loops show."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.float64)
    freq = (1.0 / period) * (1.0 + 0.12 * np.sin(2 * np.pi * t / (n / 2.3)))
    phase = 2 * np.pi * np.cumsum(freq)
    amp = 1.0 + 0.4 * np.sin(2 * np.pi * t / (n / 1.7))
    return amp * np.sin(phase) + 0.5 * rng.normal(size=n) + 0.002 * t


def test_irregular_oscillation_is_found_after_band_pass() -> None:
    plain = [detect_oscillation(_drifting(3000, 60.0, s), 1.0) for s in range(5)]
    found = [detect_oscillation(_drifting(3000, 60.0, s), 1.0, SPECTRAL) for s in range(5)]
    assert sum(r.oscillating for r in found) >= 4 > sum(r.oscillating for r in plain)
    for r in found:
        if r.oscillating:
            assert r.period_s is not None and 45.0 < r.period_s < 80.0


def test_too_short_a_record_says_so() -> None:
    t = np.arange(500, dtype=np.float64)
    x = np.sin(2 * np.pi * t / 250.0) + 0.05 * np.random.default_rng(4).normal(size=t.size)
    r = detect_oscillation(x, 1.0, SPECTRAL)
    assert not r.oscillating
    assert "record too short to judge" in r.reason, r.reason


def test_three_clear_cycles_of_a_slow_loop_are_enough() -> None:
    """Slow loops at 60-s sampling show three or four cycles in a record (issue 26 item 3)."""
    rng = np.random.default_rng(5)
    t = np.arange(720, dtype=np.float64)
    for period in (180.0, 230.0):
        x = np.sin(2 * np.pi * t / period) + 0.1 * rng.normal(size=t.size) + 0.001 * t
        r = detect_oscillation(x, 60.0, SPECTRAL)
        assert r.oscillating, r.reason
        assert r.period_s is not None and abs(r.period_s / 60.0 - period) < 0.15 * period


def test_two_oscillations_at_once_are_both_listed() -> None:
    """A slow external cycle with a faster limit cycle on top: both reported, dominant first."""
    rng = np.random.default_rng(6)
    t = np.arange(6000, dtype=np.float64)
    x = (
        2.0 * np.sin(2 * np.pi * t / 400.0)
        + 0.7 * np.sin(2 * np.pi * t / 37.0)
        + 0.2 * rng.normal(size=t.size)
    )
    r = detect_oscillation(x, 1.0, SPECTRAL)
    assert r.oscillating
    periods = [c.period_s for c in r.components]
    assert len(periods) == 2, periods
    assert 360 < periods[0] < 440 and 33 < periods[1] < 41, periods


def _noise(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    e = rng.normal(size=n)
    if kind == "white":
        return e
    if kind == "coloured":
        phi = rng.uniform(0.5, 0.999)
        x = np.empty(n)
        x[0] = e[0]
        for k in range(1, n):
            x[k] = phi * x[k - 1] + e[k]
        return x
    if kind == "walk":
        return np.cumsum(e)
    x = 0.1 * e
    for s in rng.integers(0, n, 5):
        x[s:] += rng.normal()
    return x


def test_false_alarms_on_signals_without_an_oscillation() -> None:
    """White and coloured noise (AR(1), φ 0.5-0.999), random walks and steps, 300 to 10,000
    samples: at most 2 % read as oscillating (measured 1.1 % on 2,100 such records)."""
    rng = np.random.default_rng(0)
    calls = []
    for kind in ("white", "coloured", "walk", "steps"):
        for _ in range(60):
            n = int(rng.choice([300, 1000, 3000, 10000]))
            calls.append(detect_oscillation(_noise(kind, n, rng), 1.0, SPECTRAL).oscillating)
    assert sum(calls) <= 0.02 * len(calls), sum(calls)


@pytest.mark.skipif(
    not (DATA / "labels.csv").is_file(),
    reason=f"ISDB oscillation records not found at {DATA} (../shared is not beside the repo)",
)
def test_isdb_oscillation_dev_balanced_accuracy() -> None:
    """What ``score_real.py oscillation`` measures with the CLI (measured 0.914); the floor is
    issue 46's transfer figure, 0.90."""
    hits = {True: [], False: []}  # type: dict[bool, list[bool]]
    for r in csv.DictReader((DATA / "labels.csv").open()):
        rows = list(csv.DictReader((DATA / r["file"]).open()))
        op = np.array([float(x["op"]) for x in rows])
        t = np.array([float(x["t"]) for x in rows])
        ok = np.isfinite(op)
        op = np.interp(np.arange(op.size), np.flatnonzero(ok), op[ok])
        ts = float(np.median(np.diff(t)))
        label = r["oscillating"] == "1"
        hits[label].append(detect_oscillation(op[-200_000:], ts, SPECTRAL).oscillating == label)
    recall = sum(hits[True]) / len(hits[True])
    specificity = sum(hits[False]) / len(hits[False])
    assert 0.5 * (recall + specificity) >= 0.90, (recall, specificity)
    assert specificity >= 0.85


def test_the_chain_lists_the_oscillations_it_finds() -> None:
    """``diagnose`` uses the same detector and reports ``oscillations`` (contracts §2)."""
    from plantcheck.diagnosis import diagnose
    from plantcheck.simulator.cases import generate_cases
    from plantcheck.simulator.loop import simulate_loop

    case = next(c for c in generate_cases(seed=1) if c.cause == "external_disturbance")
    run = simulate_loop(case.config)
    d = diagnose(run.pv, run.op, case.config.sample_time_s, sp=run.sp, loop_type=case.loop_type)
    out = d.to_dict()
    assert out["oscillating"], out["notes"]
    assert out["oscillations"], out
    first = out["oscillations"][0]
    assert first["period_s"] == out["oscillation"]["period_s"]
    assert set(first) == {"period_s", "amplitude", "regularity", "power_share"}
