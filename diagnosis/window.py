"""Window checks before any diagnosis (methods.md §1 and §3.2 steps IM/AIM 1–3).

Decides whether a window can be judged at all and prepares the signals for the tests:
gaps and NaN, manual mode, frozen sensor, quantisation/compression, OP saturation and
set-point changes (GI/DI indices, PCU; definitions are our reconstruction [R]).

Units: OP in % (0–100); PV and SP in engineering units (ratios are unit-free).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import (
    BoolArray,
    FloatArray,
    distinct_count,
    drawn_line_steps,
    moving_average,
    noise_sigma,
    sigma_from_second_differences,
)

IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class WindowParams:
    """Thresholds of the window checks; every one is a default to calibrate [R unless noted]."""

    min_samples: int = 100
    """Fewer usable samples than this -> ``insufficient_data``."""
    max_missing_fraction: float = 0.05
    """More missing (NaN) samples than this fraction -> ``data_quality`` (methods §1.1)."""
    max_fill_gap: int = 3
    """Gaps of at most this many samples are filled (forward fill, methods §1.1)."""
    min_auto_fraction: float = 0.9
    """Less automatic-mode time than this -> ``manual_mode`` (methods §1.2)."""
    quantised_unique_fraction: float = 0.2
    """PV with fewer distinct values than this fraction is quantised or compressed (§1.3, [V])."""
    quantised_min_levels: int = 4
    """PV with fewer distinct levels than this cannot be judged -> ``data_quality``. A healthy
    loop held within ±2 steps of a coarse historian shows 5-7 levels in a window: still
    judged, with the quantisation noted (generated windows: 4 such healthy loops were refused
    at 8) [R]."""
    frozen_fraction: float = 0.98
    """Share of unchanged consecutive PV samples above which the sensor is frozen."""
    saturation_band: float = 2.0
    """OP within this many % of 0 or 100 counts as saturated (``controllerPlotFcn3.m`` [V])."""
    saturation_pin: float = 0.1
    """A saturated OP sample lies within this many % (at most 5 % of the OP range) of the
    window's own extreme: a clamped output sits at its limit [R]."""
    saturation_fraction: float = 0.5
    """Saturated longer than this fraction of the window -> ``saturation`` ([V], not PCU)."""
    gi_limit: float = 0.1
    """Global SP index GI above this -> set point not stationary (PCU GI, [R])."""
    di_limit: float = 0.05
    """Point-wise SP index DI above this -> set-point step (PCU DI, [R])."""
    min_segment_samples: int = 300
    """The settled constant-SP stretch analysed must hold this many samples (the fewest the
    stick-slip and oscillation tests work from); shorter -> ``insufficient_data`` [R]."""
    settle_fraction: float = 0.1
    """A set-point response has settled once the control error is back within this share of
    the step (or 3 noise σ) [R, methods §3.3: T_s within ±5-10 %]."""
    step_merge_samples: int = 5
    """Set-point moves closer than this many samples are one step [R]."""
    flat_pv_op_travel: float = 1.0
    """OP moving over this many % of travel under a flat PV is named as a frozen transmitter
    or a valve that does not move (issue 46 item 7)."""
    min_clamp_samples: int = 10
    """An output at its own extreme for this many samples in a row rests at a limit [R]."""
    clamp_error_noise: float = 3.0
    """... while the control error stays off zero by this many noise σ (PV off set point) [R]."""
    max_held_runs: int = 3
    """At most this many runs of an OP held exactly still (off its extremes, under a live PV)
    are read as manual stretches: an operator's few actions, not a controller's error gap [R]."""
    frozen_min_samples: int = 30
    """A PV held bit for bit this many samples or more can be a frozen transmitter: an
    interpolating export draws PV and OP straight across shorter stretches (corpus windows
    of seed 202: 12-13 samples) [R]."""
    frozen_op_noise: float = 0.1
    """A PV held bit for bit while OP's noise σ stays under this share of its noise σ over the
    rest of the window (both read on the steps where OP moves: OP on the straight line of a
    constant error) is a frozen transmitter [R]."""
    held_pv_moving: float = 0.5
    """An OP held under a PV that moves on at least this share of the steps it moves on
    elsewhere (steps where OP does not hold) is an operator's; less, a stalled record [R]."""
    held_rest_moving: float = 0.5
    """... and only where OP changes on at least this share of the other sample steps: a
    quantised or step-hold compressed OP holds everywhere [R]."""


@dataclass(frozen=True)
class WindowReport:
    """Outcome of the window checks.

    ``verdict`` is None when the window can be diagnosed, otherwise one of
    ``insufficient_data``, ``data_quality``, ``manual_mode``, ``saturation``.
    ``segment`` is the [start, stop) sample range to analyse; the cleaned, gap-filled signals
    cover the whole window.
    """

    verdict: str | None
    notes: list[str]
    pv: FloatArray
    op: FloatArray
    sp: FloatArray
    segment: tuple[int, int]
    indices: dict[str, float] = field(default_factory=dict)
    quantised: bool = False
    sp_limited: bool = False
    """``insufficient_data`` only because set-point steps leave no long constant-SP stretch:
    tests that read the whole window (stick-slip events) still apply."""
    steps: tuple[int, ...] = ()
    """Samples at which the set point steps (their responses feed the tuning verdict)."""
    segments: tuple[tuple[int, int], ...] = ()
    """Every settled stretch long enough to analyse, longest first (``segment`` is the first):
    a loop judged segment by segment between set-point steps."""
    error_noise: float | None = None
    """Noise σ of the control error SP − PV over the cleaned window (``noise_sigma``; None
    where the checks stopped before the output stage): the tests that read the whole window
    take it from here rather than each computing it again."""
    op_noise: float | None = None
    """Noise σ of the cleaned OP, % (None where the window was refused)."""
    bridged: BoolArray | None = None
    """Samples of the gaps longer than ``max_fill_gap`` that the checks drew a straight line
    across (missing, or left out in manual or as a frozen transmitter); None where there were
    none: what the record shows there is the checks' line, not the loop."""


def _runs(mask: BoolArray) -> tuple[IntArray, IntArray]:
    """[start, stop) of each run of True in ``mask``."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def fill_short_gaps(x: FloatArray, max_gap: int) -> tuple[FloatArray, int]:
    """Fill NaN runs: runs of <= ``max_gap`` forward-filled, longer ones linearly interpolated.

    Returns the filled array and the length of the longest gap.
    """
    bad = ~np.isfinite(x)
    if not bad.any():
        return x, 0
    good_idx = np.flatnonzero(~bad)
    if good_idx.size == 0:
        return x, int(x.size)
    run_start, run_stop = _runs(bad)
    longest = int((run_stop - run_start).max())
    idx = np.arange(x.size)
    filled = np.interp(idx, good_idx, x[good_idx])
    # forward-fill short runs (methods §1.1); long runs keep the interpolation
    prev = np.maximum.accumulate(np.where(bad, 0, idx))
    short = np.zeros(x.size, dtype=bool)
    for a, b in zip(run_start, run_stop, strict=True):
        if b - a <= max_gap and a > 0:
            short[a:b] = True
    filled[short] = x[prev[short]]
    return np.asarray(filled, dtype=np.float64), longest


@dataclass
class _Window:
    """The window as the checks leave it, stage by stage: the signals (gap-filled once the gap
    stage has run), the notes and indices so far, and what the later stages need."""

    pv: FloatArray
    op: FloatArray
    sp: FloatArray
    n: int
    auto: BoolArray | None
    sp_column: bool
    """Whether a set point was given at all (a missing one is noted)."""
    notes: list[str] = field(default_factory=list)
    indices: dict[str, float] = field(default_factory=dict)
    pv_range: float = 0.0
    n_levels: int = 0
    quantised: bool = False
    clamp: Clamp | None = None
    error_noise: float = 0.0
    """Noise σ of SP − PV, from the output stage on."""
    bridged: BoolArray | None = None
    """Samples the gap stage filled in (``WindowReport.bridged``)."""

    def stop(self, verdict: str, segment: tuple[int, int] | None = None) -> WindowReport:
        """The report of a window refused with ``verdict``."""
        return WindowReport(
            verdict, self.notes, self.pv, self.op, self.sp, segment or (0, self.n), self.indices
        )


def _length(w: _Window, p: WindowParams) -> WindowReport | None:
    """Too few samples for any test."""
    if w.n >= p.min_samples:
        return None
    w.notes.append(f"only {w.n} samples; at least {p.min_samples} are needed for a diagnosis")
    return w.stop("insufficient_data")


def _long_runs(steps: BoolArray, span: int, min_samples: int) -> list[tuple[int, int]]:
    """[start, stop) samples of each run of True in ``steps`` (entry k of a ``span``-th
    difference spans samples k to k + ``span``) that covers at least ``min_samples`` samples."""
    starts, stops = _runs(steps)
    return [
        (a, b + span)
        for a, b in zip(starts.tolist(), stops.tolist(), strict=True)
        if b + span - a >= min_samples
    ]


def _exact_holds(x: FloatArray, min_samples: int, to_end: bool = False) -> list[tuple[int, int]]:
    """[start, stop) of each run of at least ``min_samples`` samples that repeat one value bit
    for bit (NaN never holds); one that runs to the window's last sample only if ``to_end``."""
    still = np.diff(x) == 0.0
    if int(np.count_nonzero(still)) < min_samples - 1:
        return []  # no run long enough: most windows stop here
    n = int(x.size)
    return [(a, b) for a, b in _long_runs(still, 1, min_samples) if to_end or b < n]


def _mask(n: int, runs: list[tuple[int, int]]) -> BoolArray:
    """The samples of ``runs`` ([start, stop) each) in an ``n``-sample mask."""
    mask = np.zeros(n, dtype=bool)
    for a, b in runs:
        mask[a:b] = True
    return mask


def held_output(op: FloatArray, pv: FloatArray, p: WindowParams | None = None) -> BoolArray:
    """Samples where OP is held exactly still under a live PV, away from its own extremes:
    a controller in manual that the record does not flag (issue 46 item 1).

    A PI law in automatic moves its output with every live PV sample (the proportional action
    alone does), so an output that repeats its value bit for bit for ``min_clamp_samples`` or
    more while PV keeps changing (on at least ``held_pv_moving`` of the share of steps it
    changes on where OP does not hold: a compressed or quantised PV changes on few anywhere)
    was not computed by the controller: an operator held it (Åström & Hägglund, 2006, §3.5,
    bumpless transfer: OP stands still in manual and the controller takes over from it). Held
    at the window's own extreme it is a clamp, read by the output stage. Left alone where OP
    also holds on more than ``1 - held_rest_moving`` of the other steps, neither held nor at a
    clamp (a quantised or step-hold compressed OP), or where more than ``max_held_runs`` runs
    hold (a controller with an error gap). A hold that runs to the window's end is left alone
    too: an interpolating historian's export holds the last stored value there (corpus windows
    of seed 202: 39 of 2,000 end so, none hold inside), so only a stretch OP leaves again, the
    return to automatic, is read.
    OP in %; PV in engineering units.
    """
    p = p or WindowParams()
    n = int(op.size)
    holds = _exact_holds(op, p.min_clamp_samples)
    if not holds:
        return np.zeros(n, dtype=bool)
    extremes = (float(np.nanmax(op)), float(np.nanmin(op)))  # a clamp's, read by _output
    still = _mask(n, holds)
    pv_moves = np.diff(pv) != 0.0
    outside = ~(still[1:] | still[:-1])
    # how often PV moves where OP does not hold: a compressed or quantised PV rarely does
    moving = min(float(np.mean(pv_moves[outside])), 1.0) if outside.any() else 1.0
    runs = [
        (a, b)
        for a, b in holds
        if float(op[a]) not in extremes
        # a PV standing still too is a stalled record, not an operator
        and float(np.mean(pv_moves[a : b - 1])) >= max(p.held_pv_moving * moving, 1e-12)
    ]
    if not runs or len(runs) > p.max_held_runs:
        return np.zeros(n, dtype=bool)
    held = _mask(n, runs)
    # the steps that must move: neither held nor at a clamp (a saturated loop's OP rests at
    # its limit for up to four fifths of a window, leaving it for a sample or two at times)
    off = _mask(n, runs) | np.isin(op, extremes)
    rest = ~(off[1:] | off[:-1])
    if rest.any() and float(np.mean(np.diff(op)[rest] == 0.0)) > 1.0 - p.held_rest_moving:
        return np.zeros(n, dtype=bool)
    return held


def _straight_runs(x: FloatArray, min_samples: int) -> BoolArray:
    """Samples of runs of at least ``min_samples`` on one sloping straight line (second
    differences within float rounding of zero, first ones not zero): an interpolating export's
    segments, or a ramp no noise reaches."""
    n = int(x.size)
    if n < 3:
        return np.zeros(n, dtype=bool)
    return _mask(n, _long_runs(drawn_line_steps(x), 2, min_samples))


def frozen_pv(pv: FloatArray, op: FloatArray, p: WindowParams | None = None) -> BoolArray:
    """Samples where the PV repeats its value bit for bit while OP moves on a straight line:
    a transmitter frozen for part of the window (issue 46 items 1 and 7), or a DCS holding the
    last good value of a failed measurement.

    The controller sees the frozen value too, so its error is constant and a PI law's output
    ramps on a straight line, the integral of a constant, without the measurement noise it
    carries elsewhere: OP's noise σ over the run under ``frozen_op_noise`` × its noise σ over
    the rest of the window, both on the steps where OP moves (``_moving_noise``). A live PV
    that only the historian holds (quantised, compressed, an interpolating export's tail)
    leaves the controller's OP as noisy as anywhere, and a sticky valve's stuck phase likewise
    (the controller sees the live PV): neither is read.
    Runs of at least ``frozen_min_samples`` samples, at most ``max_held_runs`` of them, OP
    moving within each; an OP record that runs on straight lines outside them too (an
    interpolating export: corpus windows of seed 202 held PV and OP straight together in 11
    of 2,000 such records) is left alone.
    PV in engineering units; OP in %.
    """
    p = p or WindowParams()
    n = int(pv.size)
    # a transmitter frozen now holds to the window's end: the live reading tells
    holds = _exact_holds(pv, p.frozen_min_samples, to_end=True)
    if not holds or len(holds) > p.max_held_runs:
        return np.zeros(n, dtype=bool)
    rest = ~_mask(n, holds)
    op_noise = _moving_noise(op[rest], 4)
    if not op_noise > 0.0 or _straight_runs(op, p.min_clamp_samples)[rest].any():
        return np.zeros(n, dtype=bool)  # an OP record that draws straight lines by itself
    ratio = p.frozen_op_noise
    runs = [
        (a, b) for a, b in holds if _moving_noise(op[a:b], p.min_clamp_samples) < ratio * op_noise
    ]
    return _mask(n, runs)


def _moving_noise(x: FloatArray, least: int) -> float:
    """Noise σ of ``x`` from its second differences where it moves (both first differences
    around one non-zero), as ``noise_sigma`` reads it: an output resting at a clamp is not
    noiseless, only still. NaN with fewer than ``least`` such steps (nothing to read)."""
    d = np.diff(x)
    dd = np.diff(d)[(d[:-1] != 0.0) & (d[1:] != 0.0)]
    dd = dd[np.isfinite(dd)]  # a gap in OP leaves the rest to read
    if dd.size < max(least, 1):
        return float("nan")
    return sigma_from_second_differences(dd)


@dataclass(frozen=True)
class AutomaticStretch:
    """The part of a window to judge alone: samples [start, stop), the loop in automatic
    throughout, and the share of the window in manual around it."""

    start: int
    stop: int
    manual_share: float


def automatic_stretch(
    auto: BoolArray | None, p: WindowParams | None = None
) -> AutomaticStretch | None:
    """The longest automatic stretch of a window whose manual time (False in ``auto``: the
    mode flag's, with what ``held_output`` reads from a held OP) passes the
    ``max_missing_fraction`` a window may bridge while the loop is in automatic for at least
    ``min_auto_fraction`` of it (methods §1 judges such a window): judged alone, as the time
    after a controller change is. None where the window is judged whole or refused: less
    manual time, more, or no automatic stretch of ``min_segment_samples``."""
    p = p or WindowParams()
    if auto is None:
        return None
    manual = ~np.asarray(auto, dtype=bool)
    share = float(np.mean(manual))
    if share <= p.max_missing_fraction or 1.0 - share < p.min_auto_fraction:
        return None
    starts, stops = _runs(~manual)
    k = int(np.argmax(stops - starts))
    a, b = int(starts[k]), int(stops[k])
    if b - a < max(p.min_samples, p.min_segment_samples):
        return None
    return AutomaticStretch(a, b, share)


def _held(w: _Window, p: WindowParams) -> WindowReport | None:
    """An unflagged manual stretch (``held_output``) is left out as the mode flag's would be."""
    held = held_output(w.op, w.pv, p)
    if not held.any():
        return None
    w.indices["held_output_fraction"] = float(np.mean(held))
    w.notes.append(
        f"OP held exactly still on {100 * float(np.mean(held)):.1f} % of the window while PV "
        "kept moving: no controller in automatic does that, so the loop was in manual there "
        "(read as manual-mode samples; map the loop's mode tag to say so)"
    )
    w.auto = ~held if w.auto is None else w.auto & ~held
    return None


def _frozen(w: _Window, p: WindowParams) -> WindowReport | None:
    """A transmitter frozen for part of the window (``frozen_pv``): those samples are left
    out as missing ones, PV and OP alike (the controller acted on the frozen value)."""
    frozen = frozen_pv(w.pv, w.op, p)
    if not frozen.any():
        return None
    share = w.indices["frozen_pv_fraction"] = int(frozen.sum()) / w.n
    w.notes.append(
        f"PV repeated its value bit for bit on {100 * share:.1f} % of the window while "
        "OP ramped on a straight line (the controller saw a constant error): the transmitter "
        "froze there or the DCS held a failed measurement's last value; left out as missing "
        "(check the transmitter's live reading)"
    )
    w.pv = np.where(frozen, np.nan, w.pv)
    w.op = np.where(frozen, np.nan, w.op)
    return None


def _mode(w: _Window, p: WindowParams) -> WindowReport | None:
    """Manual mode: samples outside AUTO/CAS are left out (contracts §1); a window mostly in
    manual is not judged."""
    auto = w.auto
    if auto is None:
        return None
    auto_frac = float(np.mean(auto))
    w.indices["auto_fraction"] = auto_frac
    if auto_frac < p.min_auto_fraction:
        w.notes.append(
            f"loop in automatic only {100 * auto_frac:.0f} % of the window "
            f"(needs {100 * p.min_auto_fraction:.0f} %)"
        )
        return w.stop("manual_mode")
    if auto_frac < 1.0:
        w.pv = np.where(auto, w.pv, np.nan)
        w.op = np.where(auto, w.op, np.nan)
        w.notes.append(f"{int(np.sum(~auto))} manual-mode samples left out")
    return None


def _gaps(w: _Window, p: WindowParams) -> WindowReport | None:
    """Missing samples (methods §1.2): too many refuse the window, short gaps are filled; a
    missing set point is taken as constant at the mean PV."""
    missing = ~np.isfinite(w.pv) | ~np.isfinite(w.op)
    miss_frac = float(np.mean(missing))
    w.indices["missing_fraction"] = miss_frac
    if miss_frac >= 1.0:
        w.notes.append("PV or OP has no numeric value in the whole window")
        return w.stop("data_quality")
    if w.n - int(missing.sum()) < p.min_samples:
        w.notes.append(
            f"only {w.n - int(missing.sum())} samples with both PV and OP; "
            f"at least {p.min_samples} are needed"
        )
        return w.stop("insufficient_data")
    if miss_frac > p.max_missing_fraction:
        manual = 0 if w.auto is None else int(np.sum(~w.auto))
        if manual and (int(missing.sum()) - manual) / w.n <= p.max_missing_fraction:
            # the manual-mode samples left out as gaps are what passes the limit: the loop's
            # manual time, not the record, keeps the window from being judged
            w.notes.append(
                f"{100 * manual / w.n:.1f} % of the window in manual: more than the "
                f"{100 * p.max_missing_fraction:.0f} % a window may bridge; judge a window "
                "with less manual time"
            )
            return w.stop("manual_mode")
        share = w.indices.get("frozen_pv_fraction")
        frozen = f", the transmitter frozen on {100 * share:.1f} %" if share else ""
        w.notes.append(
            f"{100 * miss_frac:.1f} % of samples missing{frozen} "
            f"(limit {100 * p.max_missing_fraction:.0f} %)"
        )
        return w.stop("data_quality")
    sp_given = bool(np.isfinite(w.sp).any())
    w.pv, gap_pv = fill_short_gaps(np.asarray(w.pv, dtype=np.float64), p.max_fill_gap)
    w.op, gap_op = fill_short_gaps(np.asarray(w.op, dtype=np.float64), p.max_fill_gap)
    if miss_frac > 0:
        # a forward-filled sample or three draws nothing; a longer gap is a straight line
        long = _long_runs(missing, 0, p.max_fill_gap + 1)
        w.bridged = _mask(w.n, long) if long else None
        w.notes.append(
            f"{int(missing.sum())} missing samples filled (longest gap {max(gap_pv, gap_op)})"
        )
    if sp_given:
        w.sp, _ = fill_short_gaps(w.sp, p.max_fill_gap)
    else:
        if not w.sp_column:
            w.notes.append("no SP column: set point assumed constant (mean of PV)")
        w.sp = np.full(w.n, float(np.mean(w.pv)))
    return None


def _measurement(w: _Window, p: WindowParams) -> WindowReport | None:
    """Frozen sensor and quantisation (methods §1.3)."""
    w.pv_range = float(np.ptp(w.pv))
    if w.pv_range == 0.0:
        w.notes.append("PV is constant over the window (frozen sensor or no measurement)")
        _flat_pv_while_op_moves(w, p)
        return w.stop("data_quality")
    unchanged = float(np.mean(np.diff(w.pv) == 0.0))
    w.indices["pv_unchanged_fraction"] = unchanged
    if unchanged > p.frozen_fraction:
        w.notes.append(
            f"PV unchanged on {100 * unchanged:.0f} % of samples (frozen sensor or heavy "
            "historian compression)"
        )
        _flat_pv_while_op_moves(w, p)
        return w.stop("data_quality")
    w.n_levels = distinct_count(w.pv)
    unique_frac = w.n_levels / w.n
    w.indices["pv_unique_fraction"] = unique_frac
    w.quantised = unique_frac < p.quantised_unique_fraction
    return None


def _flat_pv_while_op_moves(w: _Window, p: WindowParams) -> None:
    """A PV that stays flat while OP moves (issue 46 item 7): a frozen transmitter or a valve
    that does not move, with the evidence for each. A live measurement carries noise and the
    process' own drift even behind a seized valve; a transmitter that froze (or a signal held
    by the historian) repeats its last value exactly. OP's range is in % of travel."""
    op = w.op[np.isfinite(w.op)]
    travel = float(np.ptp(op)) if op.size else 0.0
    if travel < p.flat_pv_op_travel:
        return
    # the share the measurement check read; a PV constant over the window repeats everywhere
    exact = float(w.indices.get("pv_unchanged_fraction", 1.0))
    w.notes.append(
        f"OP moved over {travel:.1f} % of travel while PV stayed flat: either the transmitter "
        f"is frozen (PV repeats its value exactly on {100 * exact:.0f} % of samples; a live "
        "measurement shows noise even when the process stands still) or the valve does not "
        "move (seized, or shut against its seat, with the process holding still); check the "
        "transmitter's live reading first, then stroke the valve"
    )


def _output(w: _Window, p: WindowParams) -> WindowReport | None:
    """OP saturation (methods §1.4) and clamps at any output limit (issue 25): a clamp over
    most of the window is ``saturation``, a constant OP without one manual mode."""
    e = w.sp - w.pv
    sigma_e = w.error_noise = noise_sigma(e)
    clamp = w.clamp = _clamped(w.op, e, sigma_e, p)
    w.indices["saturation_fraction"] = clamp.fraction
    if clamp.fraction > 0:
        err = float(np.mean(np.abs(e[clamp.mask])))
        w.indices["clamp_error_noise"] = err / sigma_e if sigma_e > 0 else 0.0
    if clamp.limit is not None:
        w.indices["op_limit"] = clamp.limit
    if float(np.ptp(w.op)) == 0.0:
        if clamp.fraction >= 1.0:
            w.notes.append(
                f"OP held at {w.op[0]:g} % over the whole window with PV kept off set point: "
                "the output sits at a limit"
            )
            return replace(w.stop("saturation"), quantised=w.quantised)
        w.notes.append("OP constant over the window: controller in manual or output frozen")
        return w.stop("manual_mode")
    if clamp.fraction > p.saturation_fraction:
        w.notes.append(
            f"OP clamped at its limit {clamp.limit:.4g} % for {100 * clamp.fraction:.0f} % of "
            "the window with PV off set point"
        )
        return replace(w.stop("saturation"), quantised=w.quantised)
    if clamp.fraction > 0:
        w.notes.append(
            f"OP at its limit {clamp.limit:.4g} % for {100 * clamp.fraction:.0f} % of the window"
        )
    return None


def _resolution(w: _Window, p: WindowParams) -> WindowReport | None:
    """PV resolution, read after the clamp (a clamped output's offset is far above any
    step): too few distinct values refuse the window, a quantised PV is noted."""
    if w.n_levels < p.quantised_min_levels:
        w.notes.append(
            f"PV takes only {w.n_levels} distinct values: too coarsely quantised to judge"
        )
        return w.stop("data_quality")
    if w.quantised:
        w.notes.append(
            f"PV quantised or compressed ({100 * w.indices['pv_unique_fraction']:.1f} % distinct "
            "values): shape-based stiction tests are less reliable"
        )
    return None


def _set_point(w: _Window, p: WindowParams) -> WindowReport:
    """Set-point stationarity, GI (global) and DI (point-wise), PCU [R]: the steps, each
    response's settling read from the data, and the settled stretches left to analyse."""
    assert w.clamp is not None
    sp_f, pv_f, op_f, n, notes, indices = w.sp, w.pv, w.op, w.n, w.notes, w.indices
    eps = 1e-12
    gi = float(np.ptp(sp_f)) / (w.pv_range + eps)
    di = float(np.max(np.abs(np.diff(sp_f)))) / (w.pv_range + eps)
    indices["sp_gi"] = gi
    indices["sp_di"] = di
    steps = np.zeros(0, dtype=np.int64)
    if gi >= p.gi_limit and di >= p.di_limit:
        step_tol = max(p.di_limit * w.pv_range, 3.0 * noise_sigma(sp_f))
        steps = np.flatnonzero(np.abs(np.diff(sp_f)) > step_tol) + 1
        # a move spread over a few samples (an operator typing, a historian interpolating) is
        # one step
        steps = steps[np.concatenate(([True], np.diff(steps) > p.step_merge_samples))]
    elif gi >= p.gi_limit:
        notes.append("set point moves slowly (cascade or ramp): analysed the control error")
    e_f = sp_f - pv_f
    usable = ~w.clamp.mask
    settling: list[int] = []
    sigma_e = w.error_noise
    for k in steps.tolist():
        end = _settled(e_f, k, float(sp_f[k] - sp_f[k - 1]), sigma_e, p)
        settling.append(end - k)
        usable[k:end] = False
    stretches = _usable_stretches(usable, steps)
    segment = stretches[0]
    seg_len = segment[1] - segment[0]
    needed = max(p.min_samples, p.min_segment_samples)
    segments = tuple(s for s in stretches if s[1] - s[0] >= needed)
    op_noise = noise_sigma(op_f)  # every report from here on carries it
    if steps.size == 0 and (w.clamp.fraction == 0 or seg_len < needed):
        return WindowReport(None, notes, pv_f, op_f, sp_f, (0, n), indices, w.quantised,
                            error_noise=sigma_e, op_noise=op_noise, bridged=w.bridged)  # fmt: skip
    if seg_len < needed:
        notes.append(
            f"{steps.size} set-point step(s) with their responses leave no settled stretch of "
            f"{needed} samples (longest {seg_len}): too short for the oscillation and tuning tests"
        )
        return WindowReport(
            "insufficient_data", notes, pv_f, op_f, sp_f, segment, indices, w.quantised, True,
            tuple(steps.tolist()), error_noise=sigma_e, op_noise=op_noise, bridged=w.bridged,
        )  # fmt: skip
    if steps.size:
        notes.append(
            f"{steps.size} set-point step(s) at sample(s) {', '.join(map(str, steps.tolist()))}; "
            f"responses settled within {max(settling)} samples; analysed the settled stretch "
            f"{segment[0]}-{segment[1]} ({seg_len} samples)"
        )
    else:
        notes.append(
            f"analysed the stretch {segment[0]}-{segment[1]} ({seg_len} samples) with the output "
            "off its limit"
        )
    indices["sp_steps"] = float(steps.size)
    return WindowReport(
        None, notes, pv_f, op_f, sp_f, segment, indices, w.quantised, False,
        tuple(steps.tolist()), segments, sigma_e, op_noise, w.bridged,
    )  # fmt: skip


REFUSING_STAGES: tuple[Callable[[_Window, WindowParams], WindowReport | None], ...] = (
    _length,
    _held,
    _frozen,
    _mode,
    _gaps,
    _measurement,
    _output,
    _resolution,
)
"""The checks that may refuse a window, in order; the set-point stage then finds what to
analyse."""


def check_window(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray | None = None,
    auto: BoolArray | None = None,
    params: WindowParams | None = None,
) -> WindowReport:
    """Run the §1 window checks on one loop window, stage by stage: length, mode, gaps,
    measurement, output, resolution, set point; the first stage that refuses the window
    gives the verdict.

    Parameters
    ----------
    pv, op:
        Process variable (engineering units) and controller output (% 0–100), NaN = gap.
    sp:
        Set point (same units as PV); None means constant set point (estimated as mean PV).
    auto:
        True where the controller is in automatic (AUTO/CAS); None means always automatic.
    """
    p = params or WindowParams()
    n = int(pv.size)
    sp_arr = np.full(n, np.nan) if sp is None else np.asarray(sp, dtype=np.float64)
    w = _Window(pv, op, sp_arr, n, auto, sp is not None)
    for stage in REFUSING_STAGES:
        if (report := stage(w, p)) is not None:
            return report
    return _set_point(w, p)


@dataclass(frozen=True)
class Clamp:
    """Where the controller output rests at a limit (its own extreme value, any level)."""

    mask: BoolArray
    fraction: float
    limit: float | None


def _clamped(op: FloatArray, e: FloatArray, sigma_e: float, p: WindowParams) -> Clamp:
    """Samples where OP rests at an output limit while PV is off set point.

    A DCS output limit can sit anywhere (55 %, say), so the limit is OP's own extreme value
    over the window, not 0 or 100 %: OP exactly at its maximum (or minimum) for at least
    ``min_clamp_samples`` in a row, the control error off zero by
    ``clamp_error_noise`` × its noise σ on average and on one side over the run. Near 0 or 100 %
    (``saturation_band``) any sample pinned at the extreme counts (methods §1.4, [V]).
    ``sigma_e`` is the error's noise σ (``noise_sigma(e)``).
    """
    n = int(op.size)
    op_pp = float(np.ptp(op))
    pin = min(p.saturation_pin, 0.05 * op_pp) if op_pp > 0 else 0.0
    mask = np.zeros(n, dtype=bool)
    limits: list[tuple[float, float]] = []
    op_hi, op_lo = float(np.max(op)), float(np.min(op))
    for extreme, near_end in (
        (op_hi, op_hi >= 100.0 - p.saturation_band),
        (op_lo, op_lo <= p.saturation_band),
    ):
        if near_end:
            side = np.abs(op - extreme) <= pin
        else:
            # a limit holds OP at exactly its value; a slow output only passes its extreme
            at = np.abs(op - extreme) <= 1e-9 * max(1.0, abs(extreme))
            side = np.zeros(n, dtype=bool)
            starts, stops = _runs(at)
            for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
                if b - a < p.min_clamp_samples:
                    continue
                run = e[a:b]
                off = float(np.mean(np.abs(run))) > p.clamp_error_noise * sigma_e
                one_sided = abs(float(np.mean(np.sign(run)))) >= 0.8
                if off and one_sided:
                    side[a:b] = True
        if side.any():
            limits.append((float(np.mean(side)), extreme))
            mask |= side
    limit = max(limits)[1] if limits else None
    return Clamp(mask, float(np.mean(mask)), limit)


def _settled(e: FloatArray, k: int, step: float, sigma_e: float, p: WindowParams) -> int:
    """First sample after the set-point step at ``k`` (size ``step``) where the control error,
    lightly smoothed, is back within ``settle_fraction`` of the step or 3 noise σ (``sigma_e``,
    the error's): the step response read from the data, whatever the loop's speed."""
    tail = e[k:]
    if tail.size == 0:
        return k
    smooth = moving_average(tail, 5)
    band = max(p.settle_fraction * abs(step), 3.0 * sigma_e)
    inside = np.flatnonzero(np.abs(smooth) <= band)
    return k + (int(inside[0]) if inside.size else int(tail.size))


def _usable_stretches(usable: BoolArray, steps: IntArray) -> list[tuple[int, int]]:
    """Runs of usable samples that hold no set-point step, longest first."""
    cut = usable.copy()
    cut[steps] = False  # a step sample ends a stretch even when its response was instant
    starts, stops = _runs(cut)
    if starts.size == 0:
        return [(0, 0)]
    order = np.argsort(-(stops - starts), kind="stable")
    return [(int(starts[i]), int(stops[i])) for i in order]
