"""The settings of the Hammerstein stiction quantification (``quantification``; methods.md
§6.1), apart from it: every chain's parameters hold them, while the quantification itself
(its valve-model grids and filters, 20 ms of imports) is loaded only when a window is sized.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class QuantificationParams:
    """Grid and acceptance rules of the Hammerstein quantification [R]."""

    min_window: int = 3600
    """The chain quantifies at most the last max(min_window, window_periods × period) samples."""
    window_periods: float = 40.0
    """Oscillation periods kept for quantification in long windows."""
    n_s: int = 100
    """Grid points over S in [grid_low, grid_high] × the OP excursion per half-cycle, evenly
    spaced in log S (1.6 % apart): a stick-slip model fits the data only within about 1 % of
    the true S (a slightly larger S misses slips the valve made), so the grid must be fine in
    S; J matters far less (n_ratio)."""
    grid_low: float = 0.3
    """Lower end of the S grid, × the median OP excursion between reversals."""
    grid_high: float = 1.5
    """Upper end of the S grid, × the median OP excursion (and at most s_max_fraction·pp(OP))."""
    n_ratio: int = 7
    """Grid points over J/S in [0, max_ratio]."""
    he_n_ratio: int = 5
    """Grid points over J/S for the He structure's coarse pass."""
    he_phases: int = 4
    """Starting positions tried for the He valve, evenly spaced over one slip (J) [R]."""
    he_polish_candidates: int = 6
    """The He phase polish retries the best pair of this many best S values of the coarse grid
    ..."""
    he_polish_phases: int = 20
    """... from this many starting positions over one slip, at S and half a grid step either
    side [R]."""
    j_polish_ratios: int = 11
    """J/S values tried at S* after the refinement (the J polish) ..."""
    j_polish_phases: int = 20
    """... a He valve from this many starting positions over one slip [R]."""
    max_ratio: float = 1.0
    """Largest J/S on the grid (1 = 'no offset' case; Kano allows overshoot J > S)."""
    s_max_fraction: float = 0.9
    """S never exceeds this fraction of the OP peak-to-peak range (methods §6.1)."""
    refine: int = 7
    """Points per axis of the local refinement grid."""
    max_delay_fraction: float = 0.25
    """Largest delay searched, as a fraction of the oscillation period (or 30 samples)."""
    min_cycles: float = 10.0
    """Oscillation periods the window must hold (methods §6.1: a segment of 5–10 cycles; the
    upper end, as a few slips do not fix S) (rule 1)."""
    min_fit: float = 60.0
    """Simulation FIT (%) needed for a reported estimate (methods §6.1 rule 2)."""
    max_score_ratio: float = 0.7
    """Best simulation error must be at most this × that of a linear valve (rule 3)."""
    compact_tol: float = 1.05
    """The low-error region is where the error is within this factor of the minimum (rule 4)."""
    max_region_extent: float = 0.5
    """Its S-extent must be below this fraction of S* (rule 4)."""
    rival_distance: float = 0.25
    """Rule 4c: coarse-grid S values more than this fraction of S* away from S* ..."""
    rival_tol: float = 1.15
    """... must all fit clearly worse: their best error above this factor of the minimum [R]."""
    max_structure_disagreement: float = 0.3
    """Relative difference of S* between the Kano and He valve structures (rule 5)."""
    min_stuck_fraction: float = 0.5
    """The estimated valve must be stuck at least this share of the time (rule 6) [R]."""
    max_slips_per_period: float = 4.0
    """At most this many valve slips per oscillation period (a cycle has about two) (rule 7)."""
    tradeoff_factors: tuple[float, ...] = (0.6, 0.7, 0.8, 1.25, 1.4)
    """S/S* values checked, every delay free, for the S–delay trade-off (rule 4b) [R]."""
    min_excursion_share: float = 0.4
    """S* must be at least this share of the OP travel per half-cycle (rule 8) [R]."""
    min_slip_ratio: float = 0.1
    """On a self-regulating loop J* must be at least this fraction of S*: a deadband without
    slip does not sustain a limit cycle there (rule 9) [R]."""
    structure_tie: float = 1.25
    """The two structures count as equally good when their errors are within this factor."""
    delay_scan_ratio_step: int = 3
    """The delay scan's subset: every this-many-th J/S of the grid ..."""
    delay_scan_s_stride: int = 2
    """... and every this-many-th S."""
    delay_scan_tol: float = 1.5
    """Delays of the subset pairs within this factor of its best error are tried on the grid."""
    min_moves: int = 4
    """A candidate valve trajectory must move at least this many times."""
    reference_fraction: float = 0.02
    """Deadband of the near-linear reference valve, as a fraction of S_max (rule 3)."""
    highpass_fraction: float = 0.2
    """Prefilter low edge as a fraction of the oscillation frequency (slow loads removed)."""
    highpass_order: int = 4
    """Order of the prefilter's Butterworth high-pass: steep, so that a slow external
    oscillation (a twentieth to a fifth of the loop's frequency) does not bias the ARX model
    (order 2: on a pressure loop with such an oscillation the true valve position fitted 82 %
    and a 25 % smaller S fitted better; order 4: 92 %, and the true S wins) [R]."""
    line_max_fraction: float = 0.6
    """A slow external oscillation is looked for in OP below this fraction of the loop's
    oscillation frequency ..."""
    line_prominence: float = 30.0
    """... as a spectral line standing this many times above the median power around it; OP
    and PV then both go through a notch at its frequency [R]."""
    notch_q: float = 3.0
    """Quality factor of that notch: a third of its frequency wide, which covers the line's
    frequency resolution (one cycle per window) [R]."""
    separate_oscillations: bool = True
    """Quantify at a faster oscillation found beneath the given one (a stick-slip cycle under
    a slow external oscillation; Thornhill, Huang & Zhang 2003) [R]."""
    lowpass_multiple: float = 5.0
    """Prefilter high edge in multiples of the oscillation frequency (the stick-slip harmonics
    that carry S kept, measurement noise removed) [R]."""
