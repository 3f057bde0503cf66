"""Plant-wide oscillations: loops that oscillate together, as one problem with one source
(issue 49 item 3; contracts §5 ``GET /plant/oscillations``).

An oscillation travels: a sticky valve cycles its own loop, and the cycle reaches the loops
downstream as a load. Diagnosed one by one, each of those loops reads "external disturbance";
seen together they are one group with one root cause, to be fixed at its source.

**Grouping** (Thornhill, Huang & Zhang 2003): two loops belong together when they oscillate at
a common period, harmonics considered: one of the periods each loop's diagnosis found is
within ``period_tol`` of the other's, or of an integer multiple of it (up to ``harmonics``; a
non-linear oscillation has its 2nd and 3rd harmonics). A shared period alone could be
chance (two independent loops near 60 s), so the two signals must also be *coherent* over the
same span of time: band-passed around the common frequency, their normalised
cross-correlation reaches ``min_coherence`` within half a period. Two oscillations whose
periods differ by a few per cent drift through every phase over a long window and fail it.
Groups are the connected sets of such pairs.

**Source**: the member that makes the oscillation itself: first one with a non-linearity (a
sticky valve, a dead band: its diagnosis), since a non-linearity is strongest closest to its
source and linear process dynamics downstream filter it out (Thornhill et al. 2003; Jiang,
Choudhury & Shah 2007 locate the source among the loops that carry the oscillation by the same
test); else one whose own tuning makes it cycle (aggressive). Among several, the one most
coherent with the others. Where no member does, the source is outside the group (null: look
upstream). Each member's lag behind the source is given to within half a period: the sign of
a coupling is not known, and a sinusoid shifted by half a period is the same sinusoid
inverted, so a lag cannot name the source on its own.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from plantcheck.diagnosis.signal_tools import FloatArray, bandpass, fft_ccf
from plantcheck.diagnosis.tuning_proposal import VALVE_CAUSES


@dataclass(frozen=True)
class OscillatingLoop:
    """What plant-wide analysis needs of one loop."""

    loop: str
    periods_s: tuple[float, ...]
    """The periods its diagnosis found (s), strongest first."""
    signal: FloatArray
    """Its control error (or PV) on the common time grid of all members (NaN where missing)."""
    own: str = ""
    """Evidence that the loop makes an oscillation itself (e.g. "sticky valve, S 3.0 %"),
    or ""."""
    own_rank: int = 0
    """How strong that evidence is: 0 a non-linearity (sticky valve, dead band), 1 its own
    tuning (aggressive); the strongest names the source."""


@dataclass(frozen=True)
class OscillationGroup:
    """Loops oscillating together at ``period_s`` and their likely source."""

    period_s: float
    loops: tuple[str, ...]
    source: str | None
    evidence: tuple[str, ...]
    lags_s: dict[str, float] = field(default_factory=dict)
    """Each member's lag behind the source (s), where the pair's correlation gives one."""


@dataclass(frozen=True)
class PlantOscillationParams:
    """Settings of the grouping (defaults from the literature's practice)."""

    period_tol: float = 0.1
    """Relative difference at which two periods count as one (Thornhill et al. 2003: ±10 %)."""
    harmonics: int = 3
    """Highest multiple of a period matched (2nd and 3rd harmonics of a non-linear cycle)."""
    min_coherence: float = 0.5
    """Least normalised cross-correlation of the band-passed signals within half a period."""
    band: float = 0.3
    """Half-width of the band-pass around the common frequency, relative to it."""
    min_cycles: float = 10.0
    """Fewest whole cycles of the common period the shared span must hold: two independent
    oscillations whose periods differ by δ drift apart by N·δ cycles over N cycles, so a
    short span makes near periods look coherent (two of the demo's sticky valves, 58.4 s and
    the 2nd harmonic of 28.8 s, were grouped on 4-6 cycles)."""


OWN_RANK = {**dict.fromkeys(VALVE_CAUSES, 0), "aggressive_tuning": 1}
"""Causes by which a loop makes an oscillation itself, and how strongly that names it the
source: a valve's non-linearity (0) before the loop's own tuning (1)."""


def own_oscillation(diagnosis: Mapping[str, Any]) -> tuple[str, int]:
    """(evidence, rank) that the loop of this diagnosis (contracts §2) makes its oscillation
    itself; ("", 0) when it does not."""
    cause = str(diagnosis.get("cause"))
    if cause not in OWN_RANK:
        return "", 0
    stiction = diagnosis.get("stiction") or {}
    size = stiction.get("S")
    if size is None:
        size = (stiction.get("estimate") or {}).get("S")
    what = "its valve" if OWN_RANK[cause] == 0 else "its own tuning"
    sized = f", S {float(size):.2f} %" if size is not None and cause in ("stiction",) else ""
    return f"{what} (cause {cause}{sized})", OWN_RANK[cause]


def common_period(
    a: Sequence[float], b: Sequence[float], tol: float = 0.1, harmonics: int = 3
) -> float | None:
    """The fundamental period two loops share (s): a period of one within ``tol`` of a period
    of the other or of an integer multiple of it up to ``harmonics``; None when none does.
    The first match in each loop's order of strength."""
    for p in a:
        for q in b:
            for k in range(1, harmonics + 1):
                if abs(p - k * q) <= tol * p:
                    return float(p)
                if abs(q - k * p) <= tol * q:
                    return float(q)
    return None


def _coherence(
    x: FloatArray, y: FloatArray, ts: float, period_s: float, band: float
) -> tuple[float, float]:
    """(peak |correlation|, lag of y behind x in s) of the two signals band-passed around
    1/``period_s``, within half a period."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    f0 = 1.0 / period_s
    xb = bandpass(x, ts, f0 * (1 - band), f0 * (1 + band))
    yb = bandpass(y, ts, f0 * (1 - band), f0 * (1 + band))
    max_lag = max(1, int(period_s / 2 / ts))
    lags, r = fft_ccf(xb, yb, max_lag)
    k = int(np.argmax(np.abs(r)))
    return float(abs(r[k])), float(lags[k] * ts)


def plant_oscillations(
    members: Sequence[OscillatingLoop],
    sample_time_s: float,
    params: PlantOscillationParams | None = None,
) -> list[OscillationGroup]:
    """Groups of loops oscillating together, each with its likely source; loops that share
    their oscillation with no other are in no group. Groups largest first."""
    p = params or PlantOscillationParams()
    n = len(members)
    links: dict[tuple[int, int], tuple[float, float, float]] = {}
    """(i, j) → (period, coherence, lag of j behind i in s)."""
    for i in range(n):
        for j in range(i + 1, n):
            a, b = members[i], members[j]
            period = common_period(a.periods_s, b.periods_s, p.period_tol, p.harmonics)
            if period is None:
                continue
            both = np.isfinite(a.signal) & np.isfinite(b.signal)
            if both.sum() * sample_time_s < p.min_cycles * period:
                continue
            coh, lag = _coherence(a.signal, b.signal, sample_time_s, period, p.band)
            if coh >= p.min_coherence:
                links[(i, j)] = (period, coh, lag)
    groups: list[OscillationGroup] = []
    for comp in _components(n, links):
        if len(comp) < 2:
            continue
        groups.append(_group(members, comp, links))
    return sorted(groups, key=lambda g: (-len(g.loops), g.loops))


def _components(
    n: int, links: dict[tuple[int, int], tuple[float, float, float]]
) -> list[list[int]]:
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in links:
        parent[root(i)] = root(j)
    comps: dict[int, list[int]] = {}
    for i in range(n):
        comps.setdefault(root(i), []).append(i)
    return list(comps.values())


def _lag(links: dict[tuple[int, int], tuple[float, float, float]], i: int, j: int) -> float | None:
    """Lag of j behind i (s), from their link."""
    if (i, j) in links:
        return links[(i, j)][2]
    if (j, i) in links:
        return -links[(j, i)][2]
    return None


def _group(
    members: Sequence[OscillatingLoop],
    comp: list[int],
    links: dict[tuple[int, int], tuple[float, float, float]],
) -> OscillationGroup:
    inner = {k: v for k, v in links.items() if k[0] in comp and k[1] in comp}
    period = float(np.median([v[0] for v in inner.values()]))
    loops = tuple(sorted(members[i].loop for i in comp))
    # how strongly each member shares the group's oscillation: its coherences summed
    strength = {i: sum(v[1] for k, v in inner.items() if i in k) for i in comp}
    own = [i for i in comp if members[i].own]
    if not own:
        return OscillationGroup(
            round(period, 1),
            loops,
            None,
            (
                "no member makes the oscillation itself (no sticky valve, no aggressive "
                "tuning): it comes from outside these loops, look upstream",
            ),
        )
    best = min(members[i].own_rank for i in own)
    src = max((i for i in own if members[i].own_rank == best), key=lambda i: strength[i])
    evidence = [f"{members[src].loop}: {members[src].own}"]
    others = [members[i].loop for i in own if i != src]
    if others:
        evidence.append(f"also oscillating of their own: {', '.join(others)}")
    half = period / 2
    lags_s = {}
    for j in comp:
        lag = _lag(links, src, j) if j != src else None
        if lag is not None:
            lags_s[members[j].loop] = round(lag % half, 1)
    for name, lag in sorted(lags_s.items()):
        evidence.append(f"{name} lags {members[src].loop} by {lag:.1f} s (modulo half a period)")
    return OscillationGroup(round(period, 1), loops, members[src].loop, tuple(evidence), lags_s)
