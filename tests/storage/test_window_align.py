"""``storage.window.align`` against placing the samples one by one (its fast paths: a sample on
every grid point is a copy, a held signal's sorted samples are runs of one value)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from plantcheck.storage.window import SIGNALS, align

START_US = 1_700_000_000_000_000
STEP_US = 1_000_000


def reference(
    series: dict[str, tuple[NDArray[np.int64], NDArray[np.float64]]],
    n: int,
    before: dict[str, float],
    hold: tuple[str, ...],
) -> dict[str, list[float]]:
    """Each sample to its nearest grid point in order (the later wins), then the held signals
    carried forward from ``before`` through the points without a sample."""
    out: dict[str, list[float]] = {}
    for sig in SIGNALS:
        vals = [np.nan] * n
        has = [False] * n
        t, v = series.get(sig, (np.empty(0, np.int64), np.empty(0)))
        for ti, vi in zip(t.tolist(), v.tolist(), strict=True):
            k = round((ti - START_US) / STEP_US)
            if 0 <= k < n:
                vals[k], has[k] = vi, True
        if sig in hold and (sig in before or any(has)):
            cur = before.get(sig, np.nan)
            for k in range(n):
                if has[k]:
                    cur = vals[k]
                vals[k] = cur
        out[sig] = vals
    return out


def random_series(
    rng: np.random.Generator, n: int, kind: str
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    if kind == "every":  # one sample per grid point, jittered by less than half a step
        t = START_US + STEP_US * np.arange(n) + rng.integers(-400_000, 400_000, n)
    elif kind == "sparse":  # changes only, some on one grid point, some outside the window
        t = np.sort(rng.integers(START_US - 5 * STEP_US, START_US + (n + 5) * STEP_US, 12))
    else:  # gaps and a repeated timestamp
        t = START_US + STEP_US * np.sort(rng.choice(n, n // 2, replace=False))
        t = np.sort(np.concatenate((t, t[:3])))
    v = rng.normal(size=t.size)
    v[rng.random(t.size) < 0.05] = np.nan  # Bad samples
    return t.astype(np.int64), v


@pytest.mark.parametrize("seed", range(30))
def test_align_matches_placing_samples_one_by_one(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 200
    kinds = ["every", "sparse", "gaps", "none"]
    series = {}
    for sig in SIGNALS:
        kind = kinds[rng.integers(len(kinds))]
        if kind != "none" or sig in ("pv", "op"):
            series[sig] = random_series(rng, n, "every" if kind == "none" else kind)
    if seed % 5 == 0:  # unsorted input takes the general path
        t, v = random_series(rng, n, "sparse")
        series["sp"] = (t[::-1].copy(), v[::-1].copy())
    hold = SIGNALS if seed % 2 else ("sp", "mode")
    before = {"sp": 1.5, "mv": 40.0} if seed % 3 else {}
    win = align(series, START_US, START_US + n * STEP_US, 1.0, before, hold)
    want = reference(series, n, before, hold)
    for sig in SIGNALS:
        np.testing.assert_array_equal(win.values[sig], np.array(want[sig]), err_msg=sig)


def test_polls_that_fall_behind_read_as_a_coarser_sampling() -> None:
    """Issue 47: a collector too loaded to poll a clock-stamped plant at every device sample
    skips one in two or three; the window is then on coarser steps (three seconds here), not
    half gaps (which read as data_quality). Regular polls, an outage and a source reporting
    changes keep the median spacing."""
    rng = np.random.default_rng(4)
    n = 600
    skipped = START_US + STEP_US * np.cumsum(rng.choice([1, 2, 3], n, p=[0.3, 0.5, 0.2]))
    series = {s: (skipped, rng.normal(size=n)) for s in ("pv", "op")}
    win = align(series, START_US, int(skipped[-1]) + STEP_US, None, {}, ("sp", "mode"))
    assert win.sample_time_s == 3.0 and win.coverage > 0.95
    # a source reporting changes keeps the median spacing (two seconds here)
    assert align(series, START_US, int(skipped[-1]), None, {}, SIGNALS).sample_time_s == 2.0
    regular = START_US + STEP_US * np.arange(n)
    outage = np.concatenate([regular[:300], regular[300:] + 120 * STEP_US])
    for t in (regular, outage):
        s = {k: (t, rng.normal(size=t.size)) for k in ("pv", "op")}
        assert align(s, START_US, int(t[-1]), None, {}, ("sp", "mode")).sample_time_s == 1.0
