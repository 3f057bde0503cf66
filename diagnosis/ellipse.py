"""Apparent stiction from the PV(OP) ellipse (methods.md §6.2).

Choudhury, Shah, Thornhill & Shook (2006, CEP 14:1395): OP and PV are band-passed around the
oscillation frequency (frequency-domain Wiener filter, [0.5, 2]·f_osc), an ellipse is fitted to
the (OP, PV) cloud by direct least squares (Fitzgibbon, Pilu & Fisher 1999, in the numerically
stable form of Halíř & Flusser 1998), and the apparent stiction is the chord of the ellipse
along the OP axis through its centre, in % of OP. It is an apparent quantity, distorted by the
closed-loop dynamics: use it for ranking and trending, not as S.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from plantcheck.diagnosis.signal_tools import FloatArray, bandpass


@dataclass(frozen=True)
class EllipseResult:
    """Fitted ellipse and the apparent stiction (chord along OP through the centre, % OP)."""

    apparent_stiction: float
    center: tuple[float, float]
    conic: tuple[float, float, float, float, float, float]


def fit_ellipse(x: FloatArray, y: FloatArray) -> FloatArray | None:
    """Direct least-squares ellipse a x² + b xy + c y² + d x + e y + f = 0 (Halíř & Flusser).

    Returns the six conic coefficients, or None when no ellipse fits (degenerate cloud).
    """
    d1 = np.column_stack([x * x, x * y, y * y])
    d2 = np.column_stack([x, y, np.ones_like(x)])
    s1 = d1.T @ d1
    s2 = d1.T @ d2
    s3 = d2.T @ d2
    try:
        t = -np.linalg.solve(s3, s2.T)
    except np.linalg.LinAlgError:
        return None
    m = s1 + s2 @ t
    m = np.array([m[2] / 2.0, -m[1], m[0] / 2.0])
    try:
        _, evecs = np.linalg.eig(m)
    except np.linalg.LinAlgError:
        return None
    evecs = np.real(evecs)
    cond = 4.0 * evecs[0] * evecs[2] - evecs[1] ** 2
    ok = np.flatnonzero(cond > 0)
    if ok.size == 0:
        return None
    a1 = evecs[:, ok[0]]
    return np.concatenate([a1, t @ a1])


def apparent_stiction(
    op: FloatArray, pv: FloatArray, ts: float, period_s: float
) -> EllipseResult | None:
    """Apparent stiction (% of OP) of an oscillating loop; None when no ellipse fits."""
    f0 = 1.0 / period_s
    u = bandpass(np.asarray(op, dtype=np.float64), ts, 0.5 * f0, 2.0 * f0)
    y = bandpass(np.asarray(pv, dtype=np.float64), ts, 0.5 * f0, 2.0 * f0)
    su, sy = float(np.std(u)), float(np.std(y))
    if su == 0 or sy == 0:
        return None
    # fit on standardised coordinates for conditioning, then map back to OP units
    coef = fit_ellipse(u / su, y / sy)
    if coef is None:
        return None
    a, b, c, d, e, f = coef.tolist()
    den = b * b - 4 * a * c
    if den == 0:
        return None
    xc = (2 * c * d - b * e) / den
    yc = (2 * a * e - b * d) / den
    # chord along the OP axis through the centre: a x² + (b yc + d) x + (c yc² + e yc + f) = 0
    qa, qb, qc = a, b * yc + d, c * yc * yc + e * yc + f
    disc = qb * qb - 4 * qa * qc
    if disc <= 0 or qa == 0:
        return None
    width = math.sqrt(disc) / abs(qa) * su
    return EllipseResult(width, (xc * su, yc * sy), (a, b, c, d, e, f))
