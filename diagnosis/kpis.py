"""Loop performance indices of one window (issue 49 item 1; contracts §2 ``kpis``): the
figures control-performance tools show beside a cause.

- **Service factor**: the share of the window in automatic (from the mode signal).
- **OP limit**: the output limit OP rests at and the share of the window it rests there.
- **Harris index** (Harris 1989; Desborough & Harris 1992): the variance a minimum-variance
  controller would leave over the error's variance, 1 = minimum variance, near 0 = far from
  it. The error is modelled as an autoregression driven by white noise a (least squares,
  order ``ar_order``); its impulse response ψ gives σ²_mv = σ²_a·Σ_{i<b} ψ_i², b the process
  delay in samples (the dead time plus the one sample of the hold). Needs the dead time: the
  configured one, the one identified in the window, or none (null, with the reason).
- **Error** mean and standard deviation (SP − PV, PV units) and the **variability ratio**, the
  detrended error's σ over the loop's healthy baseline σ (``baseline.py``, the same measure).
- **Travel and reversals per day** of OP (and of the stem, MV, where measured): the signal
  passed through a play (backlash) operator of width ``deadband`` so that noise neither
  travels nor reverses; travel is the sum of the played signal's moves (% of travel),
  reversals its changes of direction (the wear figures maintenance schedules by; ISA-TR75.25.02
  counts them the same way with a resolution band).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.baseline import variability
from plantcheck.diagnosis.signal_tools import FloatArray, std

DAY_S = 86_400.0


@dataclass(frozen=True)
class KpiParams:
    """Settings of the indices."""

    ar_order: int = 20
    """Order of the error's autoregression (Desborough & Harris 1992 use 10-30)."""
    deadband: float = 0.1
    """Play of the travel and reversal count, % of travel: smaller moves are noise."""


def play(x: FloatArray, width: float) -> FloatArray:
    """The play (backlash) operator: the output follows ``x`` (finite: ``travel`` drops NaN
    first) only once it has moved ``width`` away, staying ``width`` / 2 behind it; moves within
    the band leave it where it is.

    Each sample maps the output before it to clamp(y, x − width/2, x + width/2), and clamps
    compose into clamps (Krasnosel'skii & Pokrovskii 1989 build hysteresis from such maps), so
    the output at every sample is the composition of all the clamps up to it applied to
    ``x[0]``: a prefix scan in log2(n) rounds of whole-array min and max (Hillis & Steele
    1986), a quarter of a per-sample Python loop's time. Min and max copy their operands, so
    the output is the loop's to the bit.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return np.empty_like(x)
    half = width / 2.0
    # the clamp at each sample, composed with all before it: [lo, hi] after the rounds
    lo, hi = x - half, x + half
    step = 1
    while step < x.size:
        # clamp(clamp(y, lo0, hi0), lo1, hi1) = clamp(y, clamp(lo0, lo1, hi1), clamp(hi0, ...))
        earlier_lo = np.maximum(lo[:-step], lo[step:])
        earlier_hi = np.maximum(hi[:-step], lo[step:])
        np.minimum(earlier_lo, hi[step:], out=lo[step:])
        np.minimum(earlier_hi, hi[step:], out=hi[step:])
        step *= 2
    return np.asarray(np.minimum(np.maximum(x[0], lo), hi), dtype=np.float64)


@dataclass(frozen=True)
class Travel:
    """Travel (% of travel) and reversals per day of one signal."""

    travel_per_day: float
    reversals_per_day: float


def travel(x: FloatArray, ts: float, deadband: float = 0.1) -> Travel | None:
    """Travel and reversals per day of ``x`` (NaN samples skipped), None without samples."""
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size < 2:
        return None
    moves = np.diff(play(x, deadband))
    moves = moves[moves != 0.0]
    signs = np.sign(moves)
    reversals = int(np.count_nonzero(signs[1:] != signs[:-1]))
    days = x.size * ts / DAY_S
    return Travel(float(np.abs(moves).sum()) / days, reversals / days)


def _lagged(x: FloatArray, p: int) -> NDArray[np.float64]:
    """Rows [x(k−1), ..., x(k−p)] for k = p .. n−1."""
    view = np.lib.stride_tricks.sliding_window_view(x, p + 1)
    return np.asarray(view[:, :-1][:, ::-1], dtype=np.float64)


def harris_index(e: FloatArray, delay_samples: int, order: int = 20) -> float | None:
    """Harris index of the error ``e`` for a process delay of ``delay_samples`` (≥ 1), from
    an AR(``order``) model by least squares; None where the window is too short."""
    e = np.asarray(e, dtype=np.float64)
    e = e[np.isfinite(e)]
    b = max(1, int(delay_samples))
    p = int(min(order, e.size // 10))
    if p < 1 or e.size < 5 * p + b:
        return None
    y = e - e.mean()
    var = float(y @ y) / y.size
    if var <= 0:
        return None
    X = _lagged(y, p)
    target = y[p:]
    coef, *_ = np.linalg.lstsq(X, target, rcond=None)
    resid = target - X @ coef
    var_a = float(resid @ resid) / resid.size
    # impulse response of 1/A(q): psi_0 = 1, psi_k = sum_j coef_j psi_{k-j}
    psi = np.zeros(b)
    psi[0] = 1.0
    for k in range(1, b):
        m = min(k, p)
        psi[k] = float(coef[:m] @ psi[k - 1 :: -1][:m])
    var_mv = var_a * float(psi @ psi)
    return float(min(1.0, var_mv / var))


def window_kpis(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray,
    ts: float,
    *,
    auto_share: float | None,
    op_limit: float | None,
    op_limit_share: float,
    dead_time_s: float | None,
    dead_time_source: str,
    baseline_sd: float | None,
    mv: FloatArray | None = None,
    params: KpiParams | None = None,
) -> dict[str, Any]:
    """The ``kpis`` object of a window (contracts §2) with ``dead_time_source`` (configured,
    identified, or why there is none) and the Harris index's ``harris_note`` when null."""
    p = params or KpiParams()
    e = np.asarray(sp, dtype=np.float64) - np.asarray(pv, dtype=np.float64)
    finite = e[np.isfinite(e)]
    err_std = std(finite) if finite.size else None
    harris = None
    note = dead_time_source if dead_time_s is None else ""
    if dead_time_s is not None:
        harris = harris_index(e, round(dead_time_s / ts) + 1, p.ar_order)
        note = "" if harris is not None else "too few samples for the error's model"
    op_t = travel(op, ts, p.deadband)
    mv_t = travel(mv, ts, p.deadband) if mv is not None else None
    out: dict[str, Any] = {
        "service_factor": None if auto_share is None else round(auto_share, 3),
        "op_limit": None
        if op_limit is None or op_limit_share <= 0
        else {"value": round(op_limit, 2), "share": round(op_limit_share, 3)},
        "harris_index": None if harris is None else round(harris, 3),
        "dead_time_s": dead_time_s,
        "dead_time_source": dead_time_source if dead_time_s is not None else None,
        "error_mean": None if not finite.size else float(f"{finite.mean():.4g}"),
        "error_std": None if err_std is None else float(f"{err_std:.4g}"),
        "variability_ratio": None
        if err_std is None or not baseline_sd
        else round(variability(pv, op, sp)[0] / baseline_sd, 2),
        "op_travel_per_day": None if op_t is None else round(op_t.travel_per_day, 1),
        "op_reversals_per_day": None if op_t is None else round(op_t.reversals_per_day, 1),
        "mv_travel_per_day": None if mv_t is None else round(mv_t.travel_per_day, 1),
        "mv_reversals_per_day": None if mv_t is None else round(mv_t.reversals_per_day, 1),
    }
    if note:
        out["harris_note"] = note
    return out


def dead_time_for(
    configured_s: float | None, tuning: dict[str, Any] | None
) -> tuple[float | None, str]:
    """The dead time the Harris index uses and where it came from: the configured one, the
    one identified in this window, or None with the reason."""
    if configured_s is not None and math.isfinite(configured_s):
        return configured_s, "configured"
    model = (tuning or {}).get("model") or {}
    theta = model.get("theta_s")
    if theta is not None:
        return float(theta), "identified"
    return None, (
        "no dead time: set the loop's dead_time_s (a window whose tuning is judged with "
        "set-point steps identifies it)"
    )
