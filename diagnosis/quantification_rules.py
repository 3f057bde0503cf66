"""The reliability rules of the Hammerstein stiction estimate (methods §6.1), one function each.

``quantify_stiction`` finds the best valve model; these rules decide whether its S and J can be
reported. Each reads the fitted search (``Evidence``) and returns a ``Reason`` (a stable code
and the sentence for the note) when the estimate fails it, None when it passes. The estimate is
reliable when every rule passes; the codes let a caller count refusals by rule.

Rule numbers are those of the method notes (rules 1-9, Bacci di Capaci 2016 §4.3 for the fit
and error-ratio rules; the others [R], calibrated on ``benchmarks/quantification_accuracy.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from plantcheck.diagnosis.signal_tools import FloatArray

if TYPE_CHECKING:
    from plantcheck.diagnosis.quantification_params import QuantificationParams


class Reason(NamedTuple):
    """Why an estimate is not reported: a stable code and the sentence for the note."""

    code: str
    text: str


@dataclass(frozen=True)
class Evidence:
    """What the rules read of one window's search (S, J, excursions in % of OP)."""

    params: QuantificationParams
    integrating: bool | None
    cycles: float
    """Oscillation periods in the window."""
    period_samples: float
    n_samples: int
    model: str
    best: float
    """Smallest simulation error of the chosen valve model."""
    fit: float
    """Its fit, %."""
    s_best: float
    j_best: float
    S: FloatArray
    """Every S tried (the search's surface) ..."""
    score: FloatArray
    """... and its error."""
    other_model: str
    other_best: float
    other_s_best: float
    score_ratio: float
    """Error of the chosen model over that of a near-linear valve."""
    grid_top: float
    """S from which the estimate is within one grid step of the grid's upper edge."""
    tradeoff_S: FloatArray
    """S along the estimate's J/S line with every delay free (rule 4b) ..."""
    tradeoff_score: FloatArray
    """... and its error (empty when not computed)."""
    valve: FloatArray
    """The estimated valve's position over the window."""
    excursion: float
    """Median OP travel per half-cycle."""

    @property
    def stuck_fraction(self) -> float:
        """Share of samples the estimated valve does not move."""
        return float(np.mean(np.abs(np.diff(self.valve)) < 1e-12))


def too_few_cycles(ev: Evidence) -> Reason | None:
    """Rule 1: a few tens of cycles identify the valve; fewer leave S to chance."""
    if ev.cycles >= ev.params.min_cycles:
        return None
    return Reason(
        "few_cycles",
        f"only {ev.cycles:.1f} oscillation periods in the window: at least "
        f"{ev.params.min_cycles:g} are needed (a longer window)",
    )


def no_model(ev: Evidence) -> Reason | None:
    """No candidate valve moved often enough for an ARX model to be fitted."""
    if math.isfinite(ev.best):
        return None
    return Reason("no_model", "no candidate valve moved enough to identify a model")


def poor_fit(ev: Evidence) -> Reason | None:
    """Rule 2: the Hammerstein model must explain the PV."""
    if ev.fit >= ev.params.min_fit:
        return None
    return Reason("poor_fit", f"model fit {ev.fit:.0f} % below {ev.params.min_fit:.0f} %")


def no_better_than_linear(ev: Evidence) -> Reason | None:
    """Rule 3: the stiction model must beat a near-linear valve clearly."""
    if ev.score_ratio <= ev.params.max_score_ratio:
        return None
    return Reason(
        "like_linear",
        "stiction model explains little more than a linear valve "
        f"(error ratio {ev.score_ratio:.2f})",
    )


def on_grid_edge(ev: Evidence) -> Reason | None:
    """Rule 4a: an S on the grid's upper edge is as large as the OP excursion allows."""
    if ev.s_best < ev.grid_top:
        return None
    return Reason("grid_edge", "S* on the upper edge of the grid (as large as the OP excursion)")


def wide_region(ev: Evidence) -> Reason | None:
    """Rule 4: the low-error region must be compact in S."""
    good = ev.score <= ev.params.compact_tol * ev.best
    if not good.any():
        return None
    extent = float(ev.S[good].max() - ev.S[good].min())
    if ev.s_best > 0 and extent > ev.params.max_region_extent * ev.s_best:
        return Reason(
            "wide_region", f"S not identifiable: low-error region spans {extent:.2f} % of OP"
        )
    return None


def far_rival(ev: Evidence) -> Reason | None:
    """Rule 4c: a stick-slip fit is sharp in S (a valve model a few % off misses or adds
    slips), so an S far from S* that fits nearly as well means the data do not fix S: on slow
    loops a smaller S with a longer delay often fits as well as the true one."""
    far = np.abs(ev.S - ev.s_best) > ev.params.rival_distance * ev.s_best
    if not far.any() or not math.isfinite(ev.best):
        return None
    k = int(np.argmin(np.where(far, ev.score, np.inf)))
    if ev.score[k] > ev.params.rival_tol * ev.best:
        return None
    return Reason(
        "far_rival",
        f"S not identifiable: S = {ev.S[k]:.2f} % fits within "
        f"{100 * (ev.score[k] / ev.best - 1):.0f} % as well as S* = {ev.s_best:.2f} %",
    )


def delay_tradeoff(ev: Evidence) -> Reason | None:
    """Rule 4b: S and the delay can trade off (a smaller S slips earlier, a longer delay shifts
    the response back). Along S with J/S fixed and every delay free, no clearly different S
    may fit as well as S*."""
    if ev.tradeoff_score.size == 0:
        return None
    rivals = ev.tradeoff_S[ev.tradeoff_score <= ev.params.compact_tol * ev.best]
    if not rivals.size:
        return None
    return Reason(
        "delay_tradeoff",
        f"S not identifiable: S = {rivals.min():.2f}…{rivals.max():.2f} % fits as well "
        "with another delay",
    )


def models_disagree(ev: Evidence) -> Reason | None:
    """Rule 5: when the other valve model (Kano vs He) fits about as well, it must agree on S;
    when the data clearly prefer one structure, the other one's S does not matter."""
    close = ev.other_best <= ev.params.structure_tie * ev.best
    disagree = ev.s_best > 0 and (
        abs(ev.other_s_best - ev.s_best) / ev.s_best > ev.params.max_structure_disagreement
    )
    if not (close and disagree):
        return None
    return Reason(
        "models_disagree",
        f"valve models disagree on S ({ev.model} {ev.s_best:.2f} %, "
        f"{ev.other_model} {ev.other_s_best:.2f} %)",
    )


def rarely_stuck(ev: Evidence) -> Reason | None:
    """Rule 6: in a stick-slip cycle the valve is stuck most of the time (OP reverses soon
    after each slip); a small deadband on a smoothly cycling OP is stuck only near reversals."""
    stuck = ev.stuck_fraction
    if stuck >= ev.params.min_stuck_fraction:
        return None
    return Reason(
        "rarely_stuck",
        f"estimated valve stuck only {100 * stuck:.0f} % of the time: no stick-slip cycle",
    )


def too_many_slips(ev: Evidence) -> Reason | None:
    """Rule 7: about one slip per half-cycle. Many breakaways per period mean the model chops a
    smooth OP excursion into small steps (typically a He fit to a slow disturbance seen
    through a deadband)."""
    step = np.abs(np.diff(ev.valve))
    moving = step > 1e-12
    starts = np.flatnonzero(moving[1:] & ~moving[:-1]) + 1
    min_jump = 0.5 * ev.j_best if ev.j_best > 0.1 * ev.s_best else 0.0
    n_slips = int(np.sum(step[starts] >= min_jump))
    per_period = n_slips * ev.period_samples / max(1, ev.n_samples)
    if per_period <= ev.params.max_slips_per_period:
        return None
    return Reason(
        "many_slips",
        f"{per_period:.1f} valve slips per oscillation period: not a stick-slip cycle",
    )


def small_share_of_travel(ev: Evidence) -> Reason | None:
    """Rule 8: in a stick-slip (or backlash) cycle the OP reverses soon after the valve breaks
    free, so S is most of the OP travel per half-cycle."""
    if not (ev.excursion > 0 and ev.s_best < ev.params.min_excursion_share * ev.excursion):
        return None
    return Reason(
        "small_share",
        f"S* = {ev.s_best:.2f} % is a small part of the OP travel per half-cycle "
        f"({ev.excursion:.2f} %): the cycle is not explained by the valve",
    )


def deadband_without_slip(ev: Evidence) -> Reason | None:
    """Rule 9: a deadband alone (J = 0) does not sustain a limit cycle in a self-regulating
    loop under PI control: it takes a slip jump, or a second integrator in the process
    (McMillan, "Limit cycle periods", modelingandcontrol.com 2007). There a deadband fit means
    the cycle has another cause, or a stick-slip valve read with a too small S (a Kano valve
    with J = S/2 on slow loops fits as a deadband of 0.6 S)."""
    if not (ev.integrating is False and ev.j_best < ev.params.min_slip_ratio * ev.s_best):
        return None
    return Reason(
        "deadband_only",
        f"J* = {ev.j_best:.2f} % is a deadband without slip jump, which does not sustain a "
        "limit cycle in a self-regulating loop: the cycle is not explained by the valve",
    )


RULES: tuple[Callable[[Evidence], Reason | None], ...] = (
    too_few_cycles,
    no_model,
    poor_fit,
    no_better_than_linear,
    on_grid_edge,
    wide_region,
    far_rival,
    delay_tradeoff,
    models_disagree,
    rarely_stuck,
    too_many_slips,
    small_share_of_travel,
    deadband_without_slip,
)
"""Every rule, in the order their reasons are reported."""


def refusals(ev: Evidence) -> list[Reason]:
    """The reasons the estimate fails, in rule order (empty: reliable)."""
    return [r for rule in RULES if (r := rule(ev)) is not None]
