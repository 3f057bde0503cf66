"""Align a loop's stored samples on one time base (pure numpy; no database here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
SIGNALS = ("sp", "pv", "op", "mv", "mode")
HELD = ("sp", "mode")
"""Signals that hold their value between samples: a set point or a mode is reported only when
it changes (OPC UA data-change subscriptions report nothing while a value is constant)."""


@dataclass(frozen=True)
class LoopWindow:
    """SP/PV/OP/MV/mode on one grid of ``sample_time_s`` seconds starting at ``start_us``.

    Missing or Bad samples are NaN. ``coverage`` is the fraction of grid points where both PV
    and OP are good; ``signals`` lists which signals have any stored sample.
    """

    start_us: int
    sample_time_s: float
    t_us: NDArray[np.int64]
    values: dict[str, FloatArray]
    coverage: float
    signals: tuple[str, ...]

    def __getitem__(self, name: str) -> FloatArray:
        return self.values[name]


def median_spacing_s(ts_us: NDArray[np.int64]) -> float | None:
    """Median spacing (s) of the distinct timestamps; None with fewer than 2."""
    d = np.diff(ts_us)
    if not (d > 0).all():  # unsorted or repeated (a store returns one tag's sorted, unique)
        d = np.diff(np.unique(ts_us))
    if d.size < 1:
        return None
    return float(np.median(d)) / 1e6


POLL_COVERAGE = 0.95
"""Share of grid points a polled PV must fill for its grid (the diagnosis refuses a window
with more than 5 % missing)."""


def _filled(t: NDArray[np.int64], step_s: float) -> float:
    """Share of grid points of ``step_s`` that the samples ``t`` (µs, sorted) fill, over the
    holes of at most four steps (longer ones are outages, marked as such)."""
    gaps = np.diff(np.unique(np.rint((t - t[0]) / (step_s * 1e6))))
    gaps = gaps[gaps <= 4]
    return 1.0 - float(np.sum(gaps - 1)) / float(np.sum(gaps)) if gaps.size else 1.0


def polled_step_s(ts_us: NDArray[np.int64], median_s: float) -> float:
    """The grid step of a polled PV: its median spacing where the samples fill that grid to
    ``POLL_COVERAGE``; where polls fell behind and skipped device samples (spacings of one,
    two, three device ticks), the smallest multiple of the tick (the 10th-percentile
    spacing) they fill, so that late polls read as a coarser sampling instead of gaps."""
    t = np.unique(ts_us)
    if t.size < 10 or median_s <= 0 or _filled(t, median_s) >= POLL_COVERAGE:
        return median_s
    tick = float(np.percentile(np.diff(t), 10)) / 1e6
    for k in (1, 2, 3, 4):
        if tick > 0 and _filled(t, k * tick) >= POLL_COVERAGE:
            return k * tick
    return median_s


def align(
    series: dict[str, tuple[NDArray[np.int64], FloatArray]],
    start_us: int,
    end_us: int,
    sample_time_s: float | None = None,
    before: dict[str, float] | None = None,
    hold: tuple[str, ...] = HELD,
) -> LoopWindow:
    """Put each signal's (timestamps µs, values) on a common grid over [start, end).

    The grid step is ``sample_time_s`` or the median spacing of PV's timestamps (for a polled
    PV, one not in ``hold``, ``polled_step_s``'s coarser step where polls skipped). Each sample
    goes to its nearest grid point (the later sample wins a tie); grid points without a sample
    stay NaN, so gaps remain gaps, except for the ``hold`` signals (default SP, mode), which
    keep their last value (from ``before``, the last value stored before the window, at first)
    until the next sample; a Bad sample (NaN) ends the hold. ``hold`` names the held signals: every
    signal of a source that reports only changes (OPC UA subscriptions).
    """
    ts = sample_time_s
    if ts is None:
        pv_t = series.get("pv", (np.empty(0, np.int64), np.empty(0)))[0]
        ts = median_spacing_s(pv_t) or 1.0
        if "pv" not in hold:
            ts = polled_step_s(pv_t, ts)
    step_us = max(1, round(ts * 1e6))
    n = max(0, (end_us - start_us + step_us - 1) // step_us)
    grid = start_us + step_us * np.arange(n, dtype=np.int64)
    values: dict[str, FloatArray] = {}
    present = []
    before = before or {}
    for sig in SIGNALS:
        t, v = series.get(sig, _EMPTY)
        idx = np.rint((t - start_us) / step_us).astype(np.int64)
        if t.size:
            present.append(sig)
            if _one_per_point(idx, n):  # the usual case: nothing to place, fill or hold
                values[sig] = np.array(v, dtype=np.float64)
                continue
            ok = (idx >= 0) & (idx < n)
            idx, v = idx[ok], v[ok]
        if sig in hold and (sig in before or idx.size):
            if sig not in present:
                present.append(sig)
            values[sig] = _held(idx, v, n, before.get(sig, np.nan))
        else:
            values[sig] = np.full(n, np.nan)
            values[sig][idx] = v
    good = np.isfinite(values["pv"]) & np.isfinite(values["op"])
    coverage = float(good.mean()) if n else 0.0
    return LoopWindow(start_us, ts, grid, values, coverage, tuple(present))


_EMPTY = (np.empty(0, np.int64), np.empty(0))


def _held(idx: NDArray[np.int64], v: FloatArray, n: int, first: float) -> FloatArray:
    """``n`` grid points holding each sample's value (grid index ``idx``; the later of two on
    one point wins) until the next sample, ``first`` before the first one."""
    if not idx.size:
        return np.full(n, first)
    if bool((idx[1:] >= idx[:-1]).all()):  # sorted (as stored): runs of values
        last = np.append(idx[1:] != idx[:-1], True)
        idx, v = idx[last], v[last]
        edges = np.concatenate(([0], idx, [n]))
        return np.repeat(np.concatenate(([first], v)), np.diff(edges))
    out = np.full(n, np.nan)
    out[idx] = v
    has = np.zeros(n, dtype=bool)
    has[idx] = True
    last_at = np.maximum.accumulate(np.where(has, np.arange(n), -1))
    return np.where(last_at >= 0, out[np.maximum(last_at, 0)], first)


def _one_per_point(idx: NDArray[np.int64], n: int) -> bool:
    """Whether grid indices ``idx`` (of sorted timestamps) are exactly 0, 1, ..., n - 1: every
    grid point has one sample, so aligning is a copy."""
    return (
        idx.size == n
        and n > 0
        and idx[0] == 0
        and idx[-1] == n - 1
        and bool((idx[1:] > idx[:-1]).all())
    )
