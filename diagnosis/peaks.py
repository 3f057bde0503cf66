"""Peak finding in numpy alone: the two uses of ``scipy.signal.find_peaks`` the chain makes.

``scipy.signal`` takes half a second to import (it pulls in ``scipy.stats`` and
``scipy.interpolate``), longer than the whole standard chain takes on a day of data; a CLI
diagnosis of one record would spend most of its time importing it (issue 29). These functions
return exactly the peaks ``find_peaks`` returns for the same arguments (same local maxima and
plateau midpoints, same prominences, same priority order for the distance rule), which the
tests check against SciPy on random, quantised and plateau-rich signals.

Definitions follow SciPy's (Virtanen et al., 2020): a peak is a sample (or the middle of a flat
run) higher than both neighbours; its prominence is its height above the higher of the lowest
points on each side before a higher sample (or the signal's end).
"""

from __future__ import annotations

from bisect import bisect_left
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import FloatArray, segment_min

IntArray = NDArray[np.int64]


class _Runs(NamedTuple):
    """Runs of equal consecutive samples: first and last index, and value."""

    starts: IntArray
    ends: IntArray
    level: FloatArray

    def middles(self, runs: IntArray) -> IntArray:
        """The middle sample of each of ``runs`` (rounded down, as SciPy places a flat top)."""
        return np.asarray((self.starts[runs] + self.ends[runs]) // 2, dtype=np.int64)

    def turning(self) -> IntArray:
        """The first and last runs and those higher or lower than both neighbouring runs."""
        rising = self.level[1:] > self.level[:-1]
        return np.flatnonzero(np.concatenate(([True], rising[1:] != rising[:-1], [True])))


def _runs(x: FloatArray) -> _Runs:
    change = np.flatnonzero(np.diff(x) != 0)
    starts = np.concatenate(([0], change + 1))
    ends = np.concatenate((change, [x.size - 1]))
    return _Runs(starts, ends, x[starts])


def _top_runs(level: FloatArray) -> IntArray:
    """Runs higher than both neighbouring runs (never the first or last)."""
    return np.flatnonzero((level[1:-1] > level[:-2]) & (level[1:-1] > level[2:])) + 1


def local_maxima(x: FloatArray) -> IntArray:
    """Samples higher than both neighbours; a flat top counts once, at its middle (rounded
    down), as in ``scipy.signal.find_peaks``. The first and last samples are never peaks."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3:
        return np.zeros(0, dtype=np.int64)
    inner = x[1:-1]
    if not np.any(x[1:] == x[:-1]):
        # no flat run: a peak is a sample above both neighbours (a third of the runs' time)
        return np.flatnonzero((inner > x[:-2]) & (inner > x[2:])) + 1
    r = _runs(x)
    return r.middles(_top_runs(r.level))


def _max_tables(x: FloatArray) -> list[FloatArray]:
    """Range maxima of ``x`` over blocks of 2**k samples starting at each index (k = 0, 1 ...)."""
    tables = [x]
    k = 1
    while 2 * k <= x.size:
        tables.append(np.maximum(tables[-1][:-k], tables[-1][k:]))
        k *= 2
    return tables


PRUNE_LEVEL = 3
"""The quick bound that rules most noise peaks out looks 2**PRUNE_LEVEL turning points each
side."""


def _sequence_prominences(c: FloatArray, peaks: IntArray, at_least: float) -> FloatArray:
    """Prominences of ``peaks`` of the sequence ``c`` (see ``prominences``)."""
    n = c.size
    out = np.full(peaks.size, np.nan)
    v = c[peaks]
    tables = _max_tables(c)
    todo = np.arange(peaks.size)
    level = PRUNE_LEVEL
    if np.isfinite(at_least) and len(tables) > level:
        w = 1 << level
        lows = c
        for k in range(level):  # minima over blocks of 2**level, like the maxima
            lows = np.minimum(lows[: -(1 << k)], lows[1 << k :])
        inner = (peaks >= w) & (peaks + w <= n - 1)
        i, vi = peaks[inner], v[inner]
        # a higher point within w on a side: that side's base is no lower than the lowest
        # point of those w + 1, so the prominence is at most the peak's height above it
        bound_left = np.where(tables[level][i - w] > vi, np.minimum(lows[i - w], vi), -np.inf)
        bound_right = np.where(tables[level][i + 1] > vi, np.minimum(lows[i + 1], vi), -np.inf)
        sure_low = np.zeros(peaks.size, dtype=bool)
        sure_low[inner] = vi - np.maximum(bound_left, bound_right) < at_least
        todo = np.flatnonzero(~sure_low)
        if todo.size == 0:
            return out
    pk, vk = peaks[todo], v[todo]
    # binary lifting, both sides in one vector: extend each side by the largest power-of-two
    # blocks whose points are all <= the peak
    m = pk.size
    edge = np.concatenate([pk, pk])  # left: c[edge:peak] <= v; right: c[peak:edge + 1] <= v
    vv = np.concatenate([vk, vk])
    sign = np.concatenate([-np.ones(m, np.int64), np.ones(m, np.int64)])
    for level in range(len(tables) - 1, -1, -1):
        step = 1 << level
        block = tables[level]
        first = np.where(sign < 0, edge - step, edge + 1)  # block start
        ok = (first >= 0) & (first + step <= n)
        first = np.where(ok, first, 0)
        edge = np.where(ok & (block[first] <= vv), edge + sign * step, edge)
    left_min = segment_min(c, edge[:m], pk + 1)
    right_min = segment_min(c, pk, edge[m:] + 1)
    out[todo] = vk - np.maximum(left_min, right_min)
    return out


def prominences(x: FloatArray, peaks: IntArray, at_least: float = -np.inf) -> FloatArray:
    """Prominence of each peak (``scipy.signal.peak_prominences`` with no window): the peak's
    height above the higher of its two bases, each the lowest sample between the peak and
    the nearest strictly higher sample on that side (or the signal's end).

    The search runs over the turning points alone (the signal's ends and the runs higher or
    lower than both neighbouring runs): between two of them the signal is monotone, so the
    nearest higher point and the lowest point between are found among them. Peaks that are
    certainly below ``at_least`` get NaN without the full search: when a higher turning point
    lies within 2**``PRUNE_LEVEL`` of them on a side, that side's base is no lower than the
    lowest of those, which bounds the prominence.
    """
    x = np.asarray(x, dtype=np.float64)
    if peaks.size == 0:
        return np.zeros(0)
    r = _runs(x)
    turning = r.turning()
    run_of_peak = np.searchsorted(r.starts, peaks, side="right") - 1
    at = np.searchsorted(turning, run_of_peak)
    return _sequence_prominences(r.level[turning], at, at_least)


def prominent_extremes(x: FloatArray, prominence: float) -> tuple[IntArray, IntArray]:
    """The peaks of ``x`` and of ``-x`` with at least ``prominence``:
    ``find_peaks(x, prominence=prominence)[0]`` and ``find_peaks(-x, ...)[0]``, in one search.

    Both searches run over one sequence, the turning points of ``x``, an infinite barrier,
    and the turning points of ``-x``: a base stops at the barrier as at the signal's end.
    """
    x = np.asarray(x, dtype=np.float64)
    none = np.zeros(0, dtype=np.int64)
    if x.size < 3:
        return none, none
    r = _runs(x)
    turning = r.turning()
    top, bottom = _top_runs(r.level), _top_runs(-r.level)
    if top.size + bottom.size == 0:
        return none, none
    c = r.level[turning]
    joined = np.concatenate((c, [np.inf], -c))
    at = np.concatenate(
        (np.searchsorted(turning, top), c.size + 1 + np.searchsorted(turning, bottom))
    )
    prom = _sequence_prominences(joined, at, prominence)
    with np.errstate(invalid="ignore"):
        keep = prominence <= prom
    return r.middles(top[keep[: top.size]]), r.middles(bottom[keep[top.size :]])


def peaks_apart(x: FloatArray, height: float, distance: int) -> IntArray:
    """``scipy.signal.find_peaks(x, height=height, distance=distance)[0]``: the peaks at least
    ``height`` high, the higher one kept of any two closer than ``distance`` samples."""
    x = np.asarray(x, dtype=np.float64)
    peaks = local_maxima(x)
    peaks = peaks[height <= x[peaks]]
    return np.asarray(peaks[_apart(x, peaks, distance, None)], dtype=np.int64)


def highest_peaks_apart(x: FloatArray, height: float, distance: int, count: int) -> IntArray:
    """The ``count`` highest of ``peaks_apart(x, height, distance)``, highest first (equal
    heights in time order). The distance rule takes the peaks highest first and a kept peak
    only removes lower ones, so it stops once ``count`` are kept and the next is lower than
    them all: the stick-slip search asks for a dozen among the hundred or more peaks of a
    noisy hour, and took 80 µs for all of them."""
    x = np.asarray(x, dtype=np.float64)
    if count <= 0:
        return np.zeros(0, dtype=np.int64)
    peaks = local_maxima(x)
    peaks = peaks[height <= x[peaks]]
    kept = peaks[_apart(x, peaks, distance, count)]
    return np.asarray(kept[np.argsort(-x[kept], kind="stable")][:count], dtype=np.int64)


def _apart(x: FloatArray, peaks: IntArray, distance: int, count: int | None) -> NDArray[np.bool_]:
    """Which of ``peaks`` (positions in order) SciPy's distance rule keeps: highest first
    (ties in numpy's default argsort order, reversed, as SciPy), each kept peak removing the
    others within ``distance`` samples. With ``count``, the peaks lower than the ``count``
    highest kept are left undecided (False): none of them can be among those."""
    if peaks.size < 2 or distance <= 1:
        return np.ones(peaks.size, dtype=bool)
    at = peaks.tolist()
    heights = x[peaks]
    level = heights.tolist()
    flags = [True] * len(at)
    kept: list[float] = []  # the kept peaks' heights, highest first
    order = np.argsort(heights)[::-1].tolist()
    undecided: list[int] = []
    for rank, j in enumerate(order):
        if count is not None and len(kept) >= count and level[j] < kept[count - 1]:
            undecided = order[rank:]
            break
        if not flags[j]:
            continue
        kept.append(level[j])
        for k in range(bisect_left(at, at[j] - distance + 1), bisect_left(at, at[j] + distance)):
            flags[k] = k == j
    out = np.asarray(flags, dtype=bool)
    out[undecided] = False
    return out
