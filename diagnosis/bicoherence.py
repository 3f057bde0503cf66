"""Bicoherence-based non-Gaussianity and nonlinearity indices (methods.md §4.5).

Estimator: WOSA with Hanning windows and 50 % overlap, Kim–Powers normalisation with the
conditioning factor ε = 75th percentile of the denominator, significance threshold
b²_crit = χ²_{1−α}(2)/(2K) (Choudhury, Shah & Thornhill 2008, as implemented in astrochron).

Indices (Choudhury, Shah & Thornhill 2004, Automatica 40:1719; revised in Choudhury, Shook &
Shah 2006):
- NGI = mean over the principal domain of b̂² − b²_crit (2004 form, ``version="2004"``);
  the 2006 form (default) averages only the significant b̂² and compares that mean with the
  mean a significant value has under the null (b²_crit + 1/K), so that both read 0 for a
  Gaussian signal [M/R];
- NLI = |b̂²_max − (μ_rob + 2σ_rob)|, robust mean/std after trimming 10 % at each end;
- TNLI = Σ significant b̂².
Decision: NGI <= ngi_limit -> Gaussian (linear); else NLI > nli_limit -> nonlinear.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import FloatArray, detrend, hann, percentile
from plantcheck.diagnosis.stiction_verdict import StictionTestResult


@dataclass(frozen=True)
class BicoherenceParams:
    """Settings of the bicoherence test (methods.md §4.5, §10)."""

    nfft: int = 64
    """Segment length in samples [M: 64–128]."""
    max_segments: int = 256
    """At most this many segments (the most recent) are averaged, to bound the cost."""
    min_segments: int = 8
    """Fewer segments than this -> undecided."""
    alpha: float = 0.05
    """Significance level of b²_crit ([V])."""
    ngi_limit: float = 0.001
    """NGI at or below this -> Gaussian ([M])."""
    nli_limit: float = 0.01
    """NLI above this (and non-Gaussian) -> nonlinear ([M])."""
    version: Literal["2004", "2006"] = "2006"
    """Index generation (methods.md §4.5)."""
    samples_per_period: float = 24.0
    """The signal is decimated so that one oscillation period spans about this many samples."""


@dataclass(frozen=True)
class BicoherenceResult:
    """Indices and the linear/nonlinear reading."""

    ngi: float
    nli: float
    tnli: float
    b2_crit: float
    segments: int
    nonlinear: bool | None


@cache
def _principal_domain(nfft: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Bifrequency index pairs with 0 < f2 <= f1 and f1 + f2 < nfft/2."""
    half = nfft // 2
    f1, f2 = np.meshgrid(np.arange(1, half), np.arange(1, half), indexing="ij")
    keep = (f2 <= f1) & (f1 + f2 < half)
    return f1[keep].astype(np.intp), f2[keep].astype(np.intp)


def squared_bicoherence(
    x: FloatArray, nfft: int = 64, max_segments: int = 256
) -> tuple[FloatArray, int]:
    """Squared bicoherence b̂²(f1, f2) on the principal domain and the number of segments K."""
    step = nfft // 2
    n_seg = (x.size - nfft) // step + 1
    if n_seg < 1:
        return np.empty(0), 0
    n_seg = min(n_seg, max_segments)
    start0 = x.size - ((n_seg - 1) * step + nfft)
    idx = start0 + np.arange(n_seg)[:, None] * step + np.arange(nfft)[None, :]
    seg = x[idx]
    seg = seg - seg.mean(axis=1, keepdims=True)
    spec = np.fft.rfft(seg * hann(nfft)[None, :], axis=1)
    f1, f2 = _principal_domain(nfft)
    x1 = spec[:, f1]
    x2 = spec[:, f2]
    x3 = spec[:, f1 + f2]
    prod = x1 * x2
    bisp = np.mean(prod * np.conj(x3), axis=0)
    den = np.mean(np.abs(prod) ** 2, axis=0) * np.mean(np.abs(x3) ** 2, axis=0)
    eps = percentile(den, 75.0) if den.size else 0.0
    b2 = np.abs(bisp) ** 2 / (den + eps + 1e-300)
    return np.asarray(b2, dtype=np.float64), int(n_seg)


def bicoherence_indices(
    x: FloatArray,
    ts: float,
    period_s: float | None = None,
    params: BicoherenceParams | None = None,
) -> BicoherenceResult | None:
    """NGI, NLI, TNLI of ``x`` (control error recommended); None if the record is too short."""
    p = params or BicoherenceParams()
    xd = detrend(np.asarray(x, dtype=np.float64))
    if period_s:
        q = int(period_s / ts / p.samples_per_period)
        if q > 1:
            m = xd.size // q
            xd = xd[xd.size - m * q :].reshape(m, q).mean(axis=1)
    b2, k = squared_bicoherence(xd, p.nfft, p.max_segments)
    if k < p.min_segments or b2.size == 0:
        return None
    # chi-square quantile with 2 degrees of freedom: the exponential law's -2 ln(alpha)
    b2_crit = -2.0 * math.log(p.alpha) / (2.0 * k)
    sig = b2[b2 > b2_crit]
    if p.version == "2004":
        ngi = float(b2.mean()) - b2_crit
    else:
        ngi = (float(sig.mean()) - (b2_crit + 1.0 / k)) if sig.size else -b2_crit
    srt = np.sort(b2)
    trim = int(0.1 * srt.size)
    core = srt[trim : srt.size - trim] if srt.size - 2 * trim > 1 else srt
    nli = abs(float(srt[-1]) - (float(core.mean()) + 2.0 * float(core.std())))
    tnli = float(sig.sum())
    nonlinear = ngi > p.ngi_limit and nli > p.nli_limit
    return BicoherenceResult(ngi, nli, tnli, b2_crit, k, nonlinear)


def bicoherence_test(
    x: FloatArray, ts: float, period_s: float | None, params: BicoherenceParams | None = None
) -> StictionTestResult:
    """Stiction vote from nonlinearity: nonlinear -> stiction, linear -> no stiction."""
    res = bicoherence_indices(x, ts, period_s, params)
    if res is None:
        return StictionTestResult("bicoherence", None, "undecided", "record too short")
    detail = f"NGI = {res.ngi:.4f}, NLI = {res.nli:.3f}, K = {res.segments}"
    verdict: Literal["stiction", "no_stiction"] = "stiction" if res.nonlinear else "no_stiction"
    value = res.nli if math.isfinite(res.nli) else None
    return StictionTestResult("bicoherence", value, verdict, detail)
