"""A loop's own normal (issue 46 item 5): the variability of its control error and output in
healthy operation, against which a window's variability is read.

A loop whose error varies several times more than in its healthy weeks performs worse whatever
the tests say about why; plant practice reads variability against the loop's own history
(Desborough & Harris 1992 benchmark variance against a reference; Jelali 2006 recommends a
historical baseline where no minimum-variance model is at hand). The ratio is of standard
deviations of the linearly detrended error (PV units) and OP (% of travel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from plantcheck.diagnosis.signal_tools import FloatArray, detrend, std

DEGRADED_RATIO = 3.0
"""The error's σ at least this many times its baseline is a loop far from its own normal
(nine times the variance)."""


@dataclass(frozen=True)
class Baseline:
    """A loop's variability in healthy operation: σ of the detrended control error (PV units)
    and of OP (% of travel), and where it came from."""

    error_sd: float
    op_sd: float | None = None
    source: str = ""


def _detrended_sd(x: FloatArray) -> float:
    x = x[np.isfinite(x)]
    return std(detrend(x)) if x.size >= 3 else math.nan


def variability(
    pv: FloatArray, op: FloatArray, sp: FloatArray | None = None
) -> tuple[float, float]:
    """σ of the detrended control error and of the detrended OP over one window (NaN = gap;
    ``sp`` None: a constant set point, the error is PV about its mean)."""
    pv = np.asarray(pv, dtype=np.float64)
    e = (np.asarray(sp, dtype=np.float64) - pv) if sp is not None else -pv
    return _detrended_sd(e), _detrended_sd(np.asarray(op, dtype=np.float64))


def baseline_from(
    pv: FloatArray, op: FloatArray, sp: FloatArray | None = None, source: str = ""
) -> Baseline:
    """The baseline of a record of healthy operation."""
    e_sd, op_sd = variability(pv, op, sp)
    scale = float(np.nanmax(np.abs(pv))) if np.isfinite(pv).any() else 0.0
    if not math.isfinite(e_sd) or e_sd <= 1e-9 * max(1.0, scale):
        raise ValueError("the baseline record has no usable variability (flat or too short)")
    return Baseline(e_sd, op_sd if math.isfinite(op_sd) else None, source)
