"""Where a window's PI controller changed: a retuning applied inside the window.

A loop retuned a few minutes ago has a window that is mostly the old tuning; judged whole, it
keeps the old verdict for most of a window after the engineer applied the new setting (issue
48: a proposal applied must turn the verdict within a few diagnosis periods). The chain judges
such a window from the change on.

Method: the velocity-form PI regression of ``tuning.identify_pi`` (ΔOP = a·e(k) + b·e(k−1) + c)
fitted on both sides of every candidate split, a structural-break test in the manner of Chow
(1960); the break's place by least squares (Bai 1997). Cumulative sums of the normal equations
give every split's two fits in one pass. The best split is a change only when a PI controller
explains both sides (R² at least ``min_fit``: not a manual stretch, a clamp or a historian's
compression, where the regression is poor and nothing is cut) and the two sides' settings
differ (the proportional or the integral gain by more than ``min_rel_change`` and by ``min_z``
standard errors): one controller throughout gives the same settings on both sides whatever the
split. Moves at a clamp (OP at the window's extremes) are left out.

A change found is kept only where it shows again on rows averaged over ``confirm_block``
samples. A historian's record is not what the controller saw (rounded, held by its
compression deadband, drawn as straight lines between stored values): the regressors carry
that recording error, which biases the settings toward zero the more, the less the error
itself moves (errors in variables; Söderström 2007), so a side quiet under its loads and a
side after a set-point step read as two settings of one controller. Averaging rows averages
the recording error down and leaves a true change of the law as it was (on the corpus' loops,
``benchmarks/controller_change_accuracy.py``, 6,375 windows of five seeds: 23 changes found
where nobody retuned to none; of the retunings made, 2,710 found before and 2,655 after).
Rows where OP's record runs on a drawn straight line are left out as clamped ones are: an
interpolating export's segment between two stored values is the export's, not the law's
(with both, 2,671 of the retunings made are found).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import FloatArray, drawn_line_steps, sorted_unique
from plantcheck.diagnosis.tuning import pi_settings


@dataclass(frozen=True)
class ControllerChangeParams:
    """Thresholds of the break test (dimensionless unless named)."""

    min_fit: float = 0.9
    """R² of the PI regression on each side: a controller acts there, in automatic."""
    min_rel_change: float = 0.3
    """Relative change of the proportional or the integral gain that counts as a retuning (a
    DCS setting typed in, not the scatter of one estimate)."""
    min_z: float = 10.0
    """... and in standard errors of the difference: the regression's residuals are
    correlated, so its standard errors are optimistic and the bar is high."""
    min_side_samples: int = 200
    """Samples on each side: fewer judge nothing (the chain needs a few cycles)."""
    candidates: int = 200
    """Splits tried per window (evenly spaced): the cost stays flat with the window's length."""
    confirm_block: int = 8
    """Samples per row of the confirming regression: the change found must show again, with
    the same ``min_rel_change`` and ``min_z`` and a PI law on each side, on rows averaged over
    this many samples (1: not asked). Its fit is not asked again: averaging leaves fewer rows,
    and each side's fit was asked of the samples."""


@dataclass(frozen=True)
class PISides:
    """The PI settings on both sides of a change: Kc in % of OP per PV unit, Ti in s (None
    where the regression's integral term has the wrong sign), R² of each side's fit."""

    kc_before: float
    ti_before_s: float | None
    fit_before: float
    kc_after: float
    ti_after_s: float | None
    fit_after: float


@dataclass(frozen=True)
class ControllerChange:
    """A retuning inside the window: judged from sample ``at`` on."""

    at: int
    """First sample under the new settings."""
    sides: PISides


def find_controller_change(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray | None,
    ts: float,
    auto: NDArray[np.bool_] | None = None,
    params: ControllerChangeParams | None = None,
) -> ControllerChange | None:
    """The one retuning that best splits the window, or None (``latest_controller_change``
    looks for more after it).

    Parameters
    ----------
    pv, op, sp:
        PV and SP in engineering units, OP in % (NaN marks a gap; ``sp`` None: constant).
    ts:
        Sample time, s.
    auto:
        True where the loop is in automatic (None: always): manual rows are left out.
    """
    p = params or ControllerChangeParams()
    pv = np.asarray(pv, dtype=np.float64)
    op = np.asarray(op, dtype=np.float64)
    n = pv.size
    if n < 2 * p.min_side_samples + 2 or not (np.isfinite(pv).any() and np.isfinite(op).any()):
        return None
    x, y, ok = _rows(pv, op, sp, auto)
    sums = _PrefixSums.of(x, y, ok)
    lo, hi = p.min_side_samples, n - 1 - p.min_side_samples
    coarse = sorted_unique(np.linspace(lo, hi, p.candidates).astype(np.int64))
    best = _best_split(sums, coarse, ts, p)
    if best is None:
        return None
    # every split between the best candidate's neighbours, to the sample
    k = int(np.searchsorted(coarse, best[0]))
    fine = np.arange(coarse[max(k - 1, 0)], coarse[min(k + 1, coarse.size - 1)] + 1)
    row, sides = _best_split(sums, fine, ts, p) or best
    if p.confirm_block > 1 and not _confirmed(x, y, ok, row, ts, p):
        return None
    # ΔOP row k is op[k+1] − op[k]: row m − 1 ends at the first output under the new settings
    return ControllerChange(at=row, sides=sides)


def _rows(
    pv: FloatArray, op: FloatArray, sp: FloatArray | None, auto: NDArray[np.bool_] | None
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """The PI regression's rows: the regressors [e(k), e(k−1), 1] (3, samples − 1) and ΔOP,
    both zero on the rows left out, and which rows are kept (finite, in automatic, away from
    a clamp, not on a line an export drew)."""
    n = pv.size
    spv = np.full(n, np.nanmedian(pv)) if sp is None else np.asarray(sp, dtype=np.float64)
    e = spv - pv
    y = np.diff(op)
    ok = np.isfinite(y) & np.isfinite(e[1:]) & np.isfinite(e[:-1])
    if auto is not None:
        a = np.asarray(auto, dtype=bool)
        ok &= a[1:] & a[:-1]
    # OP held at a limit (0/100 % or a configured one: the window's extremes) is the clamp's,
    # not the PI law's: those moves are left out
    with np.errstate(invalid="ignore"):
        clamped = (op <= np.nanmin(op) + 1e-9) | (op >= np.nanmax(op) - 1e-9)
    ok &= ~(clamped[1:] | clamped[:-1])
    # ΔOP on a line an interpolating export drew between two stored values is the export's
    # segment, not the PI law's move
    ok[1:] &= ~drawn_line_steps(op)
    x = np.where(ok, np.stack([e[1:], e[:-1], np.ones(n - 1)]), 0.0)
    return x, np.where(ok, y, 0.0), ok


def _confirmed(
    x: FloatArray,
    y: FloatArray,
    ok: NDArray[np.bool_],
    at: int,
    ts: float,
    p: ControllerChangeParams,
) -> bool:
    """Whether the change at row ``at`` shows again on the rows averaged over
    ``p.confirm_block`` samples (the module's docstring says why): blocks of kept rows only,
    the block holding the jump row ``at − 1`` left out of both sides, as the search leaves
    that row out. Averaged rows are the velocity law's rows averaged: the same settings."""
    m = p.confirm_block
    blocks = ok.size // m
    xb = x[:, : blocks * m].reshape(3, blocks, m).mean(axis=2)
    yb = y[: blocks * m].reshape(blocks, m).mean(axis=1)
    okb: NDArray[np.bool_] = np.asarray(ok[: blocks * m].reshape(blocks, m).all(axis=1))
    sums = _PrefixSums.of(np.where(okb, xb, 0.0), np.where(okb, yb, 0.0), okb)
    jump = (at - 1) // m
    pb = replace(p, min_fit=0.0, min_side_samples=max(2, p.min_side_samples // m))
    return _best_split(sums, np.array([jump + 1]), ts, pb) is not None


_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
"""The distinct entries of a symmetric 3 × 3 normal matrix, row by row."""
_FULL = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])
"""Where each of the matrix's 9 entries sits among ``_PAIRS``."""


@dataclass(frozen=True)
class _PrefixSums:
    """Every prefix's normal equations of the PI regression, as running sums along contiguous
    rows: the 6 distinct entries of the symmetric X'X, X'y, y'y, Σy and the rows counted.
    The right side of a split is the whole less a prefix. (The 3 × 3 matrices summed as such,
    9 entries a sample along a strided axis, took 0.4 ms of the chain's 14 per 3,600 samples
    in 2026-11.)"""

    xx: FloatArray
    xy: FloatArray
    yy: FloatArray
    y: FloatArray
    n: FloatArray

    @classmethod
    def of(cls, x: FloatArray, y: FloatArray, ok: NDArray[np.bool_]) -> _PrefixSums:
        """``x``: the regressors as rows (3, samples), ``y``: ΔOP, both zero where not ``ok``.

        The constant regressor is 1 exactly where ``ok`` (and 0 elsewhere, as every row), so
        its products are the other row as it is: 10 running sums, in one pass, give the 12."""
        x0, x1 = x[0], x[1]
        okf = ok.astype(np.float64)
        products = [x0 * x0, x0 * x1, x0, x1 * x1, x1, okf, x0 * y, x1 * y, y * y, y]
        run = np.cumsum(np.stack(products), axis=1)
        return cls(run[:6], run[[6, 7, 9]], run[8], run[9], run[5])

    def _sides(self, at: NDArray[np.int64], less: bool) -> tuple[FloatArray, ...]:
        def pick(t: FloatArray) -> FloatArray:
            part = t[..., at]
            return np.asarray(t[..., -1:] - part if less else part, dtype=np.float64)

        xx = pick(self.xx)[_FULL].T.reshape(-1, 3, 3)
        return xx, np.ascontiguousarray(pick(self.xy).T), pick(self.yy), pick(self.y), pick(self.n)

    def left(self, at: NDArray[np.int64]) -> tuple[FloatArray, ...]:
        """(X'X, X'y, y'y, Σy, rows) of rows 0 .. ``at`` (each)."""
        return self._sides(at, False)

    def right(self, at: NDArray[np.int64]) -> tuple[FloatArray, ...]:
        """The same of the rows after ``at`` to the end."""
        return self._sides(at, True)


def _ridge_inverse(sxx: FloatArray) -> FloatArray:
    """Inverses of the stacked 3 × 3 normal matrices with a ridge of 1e-12. Where one is
    singular at that ridge (the error constant over a whole side, a frozen transmitter under
    a fixed set point: the rows [e, e, 1] are all alike, and e² · n dwarfs 1e-12), the ridge
    grows to 1e-9 of the matrices' mean diagonal: a fit of no meaning that the fit threshold
    then refuses, instead of an error that stopped the diagnosis."""
    try:
        return np.asarray(np.linalg.inv(sxx + 1e-12 * np.eye(3)), dtype=np.float64)
    except np.linalg.LinAlgError:
        scale = np.trace(sxx, axis1=-2, axis2=-1)[..., None, None] / 3.0
        ridge = (1e-9 * scale + 1e-12) * np.eye(3)
        return np.asarray(np.linalg.inv(sxx + ridge), dtype=np.float64)


def _best_split(
    sums: _PrefixSums, m: NDArray[np.int64], ts: float, p: ControllerChangeParams
) -> tuple[int, PISides] | None:
    """Among the splits ``m`` (rows of ΔOP; the left side ends at row m − 2, the right starts
    at row m) where both sides fit and their settings differ, the one of least residual; None
    where none qualifies."""
    # row m − 1 is left out of both: a positional PI's output jumps by ΔKc·e when its gain is
    # typed in, a move neither setting makes (one such row took a sluggish loop's R² to 0.3)
    left, right = sums.left(m - 2), sums.right(m - 1)
    fits, sses, coefs, covs = [], [], [], []
    for sxx, sxy, syy, sy, sn in (left, right):
        # a side of constant error: invertible, and a poor fit; the inverse serves the
        # coefficients and their covariance
        inv = _ridge_inverse(sxx)
        coef = np.einsum("nij,nj->ni", inv, sxy)
        sse = np.maximum(syy - np.einsum("ij,ij->i", coef, sxy), 0.0)
        sst = syy - sy * sy / np.maximum(sn, 1.0)
        # a side mostly in manual, clamped or in a gap judges nothing
        valid = (sst > 0) & (sn >= p.min_side_samples / 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            fits.append(np.where(valid, 1.0 - sse / sst, 0.0))
        sses.append(sse)
        coefs.append(coef)
        covs.append(inv * (sse / np.maximum(sn - 3.0, 1.0))[:, None, None])
    # the proportional gain Kc = (a − b)/2 and the integral gain Kc·Ts/Ti = a + b: a setting
    # changed when one of them moved by min_rel_change and by min_z standard errors (a gain the
    # window cannot pin down, an integral time far beyond the window, never reads as changed)
    changed = np.zeros(m.size, dtype=bool)
    for c in (np.array([0.5, -0.5, 0.0]), np.array([1.0, 1.0, 0.0])):
        g0, g1 = coefs[0] @ c, coefs[1] @ c
        var = np.einsum("i,nij,j->n", c, covs[0], c) + np.einsum("i,nij,j->n", c, covs[1], c)
        with np.errstate(invalid="ignore"):
            changed |= (np.abs(g1 - g0) > p.min_rel_change * np.maximum(np.abs(g0), np.abs(g1))) & (
                np.abs(g1 - g0) > p.min_z * np.sqrt(var)
            )
    # a PI controller's two gains share their sign on each side (Ti defined)
    (kc0, ti0), (kc1, ti1) = pi_settings(coefs[0], ts), pi_settings(coefs[1], ts)
    pi_both = np.isfinite(ti0) & np.isfinite(ti1)
    good = (fits[0] >= p.min_fit) & (fits[1] >= p.min_fit) & changed & pi_both
    if not np.any(good):
        return None
    # the break's place by least squares (Bai 1997): the smallest residual of the two fits
    i = int(np.argmin(np.where(good, sses[0] + sses[1], np.inf)))
    sides = PISides(
        kc_before=float(kc0[i]),
        ti_before_s=float(ti0[i]),
        fit_before=float(fits[0][i]),
        kc_after=float(kc1[i]),
        ti_after_s=float(ti1[i]),
        fit_after=float(fits[1][i]),
    )
    return int(m[i]), sides


def latest_controller_change(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray | None,
    ts: float,
    auto: NDArray[np.bool_] | None = None,
    params: ControllerChangeParams | None = None,
    max_changes: int = 3,
) -> ControllerChange | None:
    """The last of up to ``max_changes`` retunings (each searched for after the one before):
    its ``at`` counts from the window's first sample."""
    found: ControllerChange | None = None
    offset = 0
    for _ in range(max_changes):
        sl = slice(offset, None)
        nxt = find_controller_change(
            pv[sl], op[sl], None if sp is None else sp[sl], ts,
            None if auto is None else auto[sl], params,
        )  # fmt: skip
        if nxt is None:
            break
        offset += nxt.at
        found = ControllerChange(at=offset, sides=nxt.sides)
    return found


def change_json(change: ControllerChange, ts: float) -> dict[str, object]:
    """The diagnosis's optional ``controller_change``: when (s from the window's first
    sample) and the settings on each side (Kc in % of OP per PV unit, Ti in s)."""
    s = change.sides

    def side(kc: float, ti: float | None, fit: float) -> dict[str, float | None]:
        return {
            "Kc": round(kc, 3),
            "Ti_s": None if ti is None else round(ti, 1),
            "fit": round(fit, 3),
        }

    return {
        "at_s": round(change.at * ts, 1),
        "before": side(s.kc_before, s.ti_before_s, s.fit_before),
        "after": side(s.kc_after, s.ti_after_s, s.fit_after),
    }


def change_note(change: ControllerChange, ts: float, judged: int) -> str:
    """What the window's verdict is based on, in words (``judged``: samples since the
    change)."""
    s = change.sides

    def ti(v: float | None) -> str:
        return "-" if v is None else f"{v:.3g}"

    return (
        f"the controller was retuned {change.at * ts:.0f} s into the window (Kc "
        f"{s.kc_before:.3g} -> {s.kc_after:.3g} % per PV unit, Ti {ti(s.ti_before_s)} -> "
        f"{ti(s.ti_after_s)} s): judged on the {judged * ts:.0f} s since"
    )
