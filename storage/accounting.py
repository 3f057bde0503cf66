"""Sample accounting: were samples lost outside the outages the store marks?

A source's stored history is complete when every stretch without samples longer than a few
sampling intervals touches a gap marker (``BadNoCommunication``, no value): the connector saw
the outage and said so. A hole between two ordinary samples is a silent loss. Used by the fault
suite (``tests/service/test_fault_suite.py``) and the soak benchmark (``benchmarks/soak.py``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from plantcheck.core.status_codes import BAD_NO_COMMUNICATION


@dataclass(frozen=True)
class SampleAccount:
    """One tag's history over a run."""

    samples: int
    """Stored samples that are not gap markers (Good or Bad)."""
    gap_markers: int
    marked_s: float
    """Time inside outages: from the sample before each marker to the sample after it, s."""
    silent_holes: int
    """Holes longer than ``hole_intervals`` sampling intervals between two ordinary samples."""
    lost: int
    """Samples missing in the silent holes (hole length / interval - 1, summed)."""
    worst_silent_hole_s: float
    newest_us: int | None
    """Time of the newest ordinary sample (µs since the epoch): data flows again after the
    last outage when it is recent."""


def account_samples(
    ts_us: Sequence[int], status: Sequence[int], interval_s: float, hole_intervals: float = 4.0
) -> SampleAccount:
    """Account one tag's stored samples (any order) sampled every ``interval_s`` seconds."""
    ts = np.asarray(ts_us, dtype=np.int64)
    st = np.asarray(status, dtype=np.int64)
    order = np.argsort(ts, kind="stable")
    ts, st = ts[order], st[order]
    marker = st == BAD_NO_COMMUNICATION
    dt = np.diff(ts) / 1e6
    touches_marker = marker[:-1] | marker[1:]
    silent = (~touches_marker) & (dt > hole_intervals * interval_s)
    marked_s = 0.0
    for k in np.flatnonzero(marker).tolist():
        a = ts[k - 1] if k > 0 else ts[k]
        b = ts[k + 1] if k + 1 < ts.size else ts[k]
        marked_s += (b - a) / 1e6
    holes = dt[silent]
    return SampleAccount(
        samples=int((~marker).sum()),
        gap_markers=int(marker.sum()),
        marked_s=float(marked_s),
        silent_holes=int(silent.sum()),
        lost=int(np.sum(np.round(holes / interval_s) - 1)) if holes.size else 0,
        worst_silent_hole_s=float(holes.max()) if holes.size else 0.0,
        newest_us=int(ts[~marker][-1]) if (~marker).any() else None,
    )
