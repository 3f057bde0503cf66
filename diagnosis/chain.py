"""The PCU standard diagnosis chain (methods.md §3.2), SP/PV/OP only.

IM  window checks (``window.check_window``): data quality, manual mode, saturation, SP steps;
AIM oscillation test on the control error (Hägglund + Thornhill) and, when the loop does not
    oscillate, Hägglund's idle index for sluggish control;
FAM period and shape of the oscillation against the controller's own time scale;
SAM the applicable stiction tests and their vote (``stiction_vote``);
then the split between aggressive tuning and an external disturbance (``cause_split``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from plantcheck.diagnosis.acf_decay import acf_decay_ratio
from plantcheck.diagnosis.baseline import DEGRADED_RATIO, Baseline, variability
from plantcheck.diagnosis.bicoherence import BicoherenceParams, bicoherence_test
from plantcheck.diagnosis.cause_model import (
    CLAMP_SUPPORT,
    CauseModel,
    Decision,
    decide,
    safe_log,
    shipped_cause_model,
)
from plantcheck.diagnosis.cause_split import SplitParams, SplitResult, split_cause
from plantcheck.diagnosis.controller_change import (
    ControllerChange,
    ControllerChangeParams,
    change_json,
    change_note,
    latest_controller_change,
)
from plantcheck.diagnosis.ellipse import apparent_stiction
from plantcheck.diagnosis.evidence import (
    correlation_evidence,
    evidence_vector,
    process_evidence,
    shape_evidence,
    spectral_evidence,
    window_evidence,
)
from plantcheck.diagnosis.horch import HorchParams, horch_ccf, horch_histogram
from plantcheck.diagnosis.identification import quick_process_fit
from plantcheck.diagnosis.kpis import KpiParams, dead_time_for, travel, window_kpis
from plantcheck.diagnosis.load_recovery import load_recoveries, recovery_slowness
from plantcheck.diagnosis.oscillation import (
    SPECTRAL,
    OscillationParams,
    OscillationResult,
    detect_oscillation,
    oscillations_json,
)
from plantcheck.diagnosis.quantification_params import QuantificationParams
from plantcheck.diagnosis.result import Diagnosis, DiagnosisDraft, action_for
from plantcheck.diagnosis.shape_tests import (
    ShapeParams,
    area_ratio,
    curve_fit_index,
    relay_index,
    significant_half_cycles,
)
from plantcheck.diagnosis.signal_shape import ShapeInput, shape_input
from plantcheck.diagnosis.signal_tools import (
    BoolArray,
    FloatArray,
    SignalSpectrum,
    detrend,
    mean,
    moving_average,
    noise_sigma,
    std,
)
from plantcheck.diagnosis.step_response import (
    StepResponse,
    all_creep,
    sp_step_responses,
    step_slowness,
)
from plantcheck.diagnosis.stick_slip import (
    StickSlipParams,
    StickSlipResult,
    detect_stick_slip,
    size_from_events,
)
from plantcheck.diagnosis.stiction_verdict import StictionTestResult
from plantcheck.diagnosis.stiction_vote import (
    LOOP_TYPES,
    VoteParams,
    VoteResult,
    applicable_tests,
    curve_fit_decides,
    is_integrating,
    vote,
)
from plantcheck.diagnosis.tuning import (
    PIEstimate,
    TuningParams,
    identify_pi,
    idle_filter_s,
    idle_index,
)
from plantcheck.diagnosis.tuning_proposal import TuningSettings, tuning_for, valve_first
from plantcheck.diagnosis.valve_kpis import ValveParams, classify_valve
from plantcheck.diagnosis.window import (
    AutomaticStretch,
    WindowParams,
    WindowReport,
    automatic_stretch,
    check_window,
    fill_short_gaps,
    held_output,
)

if TYPE_CHECKING:
    from plantcheck.diagnosis.quantification import QuantificationResult


@dataclass(frozen=True)
class ChainParams:
    """Every threshold of the standard chain, grouped by module (defaults: methods.md §10)."""

    window: WindowParams = field(default_factory=WindowParams)
    oscillation: OscillationParams = SPECTRAL
    shape: ShapeParams = field(default_factory=ShapeParams)
    horch: HorchParams = field(default_factory=HorchParams)
    bicoherence: BicoherenceParams = field(default_factory=BicoherenceParams)
    vote: VoteParams = field(default_factory=VoteParams)
    tuning: TuningParams = field(default_factory=TuningParams)
    split: SplitParams = field(default_factory=SplitParams)
    quantification: QuantificationParams = field(default_factory=QuantificationParams)
    valve: ValveParams = field(default_factory=ValveParams)
    stick_slip: StickSlipParams = field(default_factory=StickSlipParams)
    cause_model: CauseModel | None = field(default_factory=shipped_cause_model, compare=False)
    """The learned model over the tests' evidence (issue 46); None: no probabilities."""
    decide_by: str = "rules"
    """``rules``: the chain's rules give the cause, the model its probability; ``learned``:
    the model's most probable cause is the verdict (``plantcheck diagnose --decision``)."""
    kpis: KpiParams = field(default_factory=KpiParams)
    dead_time_s: float | None = None
    """The loop's dead time (s) as configured, for the Harris index; None: the one identified
    in the window, if any."""
    retuning: TuningSettings = field(default_factory=TuningSettings)
    """Identification and retuning of a loop diagnosed with its tuning wrong (issue 48), and
    the form its controller takes the setting in."""
    controller_change: ControllerChangeParams | None = field(default_factory=ControllerChangeParams)
    """The search for a retuning inside the window, judged from it on (None: judge the whole
    window whatever its controller did)."""
    fast_processes: tuple[tuple[str, float], ...] = (("flow", 20.0),)
    """Loop types whose process follows the valve within this many seconds (lag and dead
    time): a flow (Kano et al. 2004 and Yamashita 2006 read the flow as the valve position).
    The stick-slip events' linear model may not explain a PV that stays flat for longer
    while OP ramps. Any bound from 10 to 60 s gives the same refinery verdicts [R]."""


@lru_cache(maxsize=1)
def default_chain_params() -> ChainParams:
    """``ChainParams()``, built once: it is frozen, nested parameters and all, so every call
    can share it (building its dozen nested defaults took 0.16 ms of a 3,600-sample
    diagnosis)."""
    return ChainParams()


def run_stiction_tests(
    e: FloatArray,
    op: FloatArray,
    pv: FloatArray,
    ts: float,
    osc: OscillationResult,
    loop_type: str,
    params: ChainParams,
    error_noise: float | None = None,
) -> dict[str, StictionTestResult]:
    """Run every stiction test that applies to ``loop_type`` on an oscillating window
    (``error_noise``: the noise σ of ``e`` where the caller has it)."""
    assert osc.period_s is not None
    period = osc.period_s
    width = max(1, round(period / ts / 20.0))
    integrating = is_integrating(loop_type)
    names = applicable_tests(loop_type)
    out: dict[str, StictionTestResult] = {}
    es = moving_average(detrend(e), width)
    sigma_e = noise_sigma(e) if error_noise is None else error_noise
    band = params.oscillation.noise_band * sigma_e / np.sqrt(width)
    min_amp = 0.3 * np.sqrt(2.0) * std(es)
    hc_e = significant_half_cycles(es, ts, band, min_amp, params.shape.min_half_samples)
    if "relay" in names:
        out["relay"] = relay_index(hc_e, params.shape)
    if "curve_fit" in names:
        sig = pv if integrating else op
        # OP carries the proportional kick of the PV noise: smooth over a tenth of the period
        ss = moving_average(detrend(sig), max(1, round(period / ts / 10.0)))
        amp = 0.3 * mean(np.abs(ss)) * np.sqrt(2.0)
        hc_s = significant_half_cycles(
            ss, ts, 0.1 * std(ss), amp, params.shape.curvefit_min_half_samples
        )
        shape = (
            replace(params.shape, curvefit_yes=params.shape.curvefit_yes_integrating)
            if integrating
            else params.shape
        )
        out["curve_fit"] = curve_fit_index(hc_s, shape)
    if "cross_correlation" in names:
        out["cross_correlation"] = horch_ccf(op, pv, ts, period, params.horch)
    if "histogram" in names:
        out["histogram"] = horch_histogram(pv, ts, period, params.horch)
    if "bicoherence" in names:
        out["bicoherence"] = bicoherence_test(e, ts, period, params.bicoherence)
    if "area_ratio" in names:
        out["area_ratio"] = area_ratio(es, hc_e, params.shape)
    return out


def _tests_json(tests: dict[str, StictionTestResult]) -> dict[str, float | str | None]:
    return {name: (r.label if r.label is not None else r.value) for name, r in tests.items()}


def _confidence_from_vote(v: VoteResult, stiction: bool) -> float:
    """Confidence of a vote-based verdict: 0.5 at the threshold, 1.0 when all tests agree."""
    if v.n_tests == 0:
        return 0.5
    agree = v.n_stiction if stiction else v.n_no_stiction
    return float(min(0.95, 0.5 + 0.5 * agree / v.n_tests))


@dataclass
class _Run:
    """One window on its way through the chain: the checked window, the settings, the draft
    diagnosis and what the steps found so far (the stick-slip events, the controller)."""

    win: WindowReport
    ts: float
    loop_type: str
    p: ChainParams
    quantify: bool
    exclude_stiction: bool
    diag: DiagnosisDraft
    events: StickSlipResult | None = None
    pi_window: PIEstimate | None = None
    gain_sign: int = 1
    stretch: _Stretch | None = None
    """The stretch the oscillation and tuning tests read, once found."""
    tests: dict[str, StictionTestResult] = field(default_factory=dict)
    """The stiction tests run on an oscillating window."""
    decay: float | None = None
    """The ACF decay ratio of the cycle, where read."""
    baseline: Baseline | None = None
    """The loop's healthy variability, when known."""


@dataclass(frozen=True)
class _Stretch:
    """The samples [a, b) the oscillation and tuning tests read, what they found there, and
    the controller identified on them."""

    a: int
    b: int
    osc: OscillationResult
    pi: PIEstimate
    on_op: bool = False
    """The oscillation was found in OP, not in the control error."""


@dataclass(frozen=True)
class _Prepared:
    """The samples the chain judges, as ``_prepare`` cut them, and what it read to cut them."""

    pv: FloatArray
    op: FloatArray
    sp: FloatArray | None
    auto: BoolArray | None
    """The mode flag's automatic samples less those ``held_output`` read as manual."""
    held: bool
    """Some manual time was read from an OP held still (no mode tag said so)."""
    change: ControllerChange | None
    """The last retuning in the window, the samples before it cut off."""
    part: AutomaticStretch | None
    """The automatic stretch judged alone, the manual time around it cut off."""


def _prepare(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray | None,
    auto: BoolArray | None,
    ts: float,
    p: ChainParams,
) -> _Prepared:
    """What the chain judges of a window, before its checks: the manual time a held OP
    shows joined to the mode flag's, then the samples after the last retuning, then the
    longest automatic stretch where the window is mostly in automatic (``automatic_stretch``).
    The fit's entry points (``chain_evidence``, ``chain_shape_input``) read the window through
    it too (evidence version 10), so that the model is fitted on the samples a diagnosis
    weighs: before, 13 of the 272,000 windows the fit reads were weighed whole where a
    diagnosis cut them (fifty-third session: a retuning the simulation never made, read on
    quantised or compressed records, 12 of them beside a clamp)."""
    pv = np.asarray(pv, dtype=np.float64)
    op = np.asarray(op, dtype=np.float64)
    auto = None if auto is None else np.asarray(auto, dtype=bool)
    held = held_output(op, pv, p.window)
    if held.any():  # manual time the record does not flag: every step below is told of it
        auto = ~held if auto is None else auto & ~held
    change = None
    if p.controller_change is not None:
        sp_a = None if sp is None else np.asarray(sp, dtype=np.float64)
        change = latest_controller_change(pv, op, sp_a, ts, auto, p.controller_change)
        if change is not None:
            k = change.at
            pv, op = pv[k:], op[k:]
            sp = None if sp_a is None else sp_a[k:]
            auto = None if auto is None else auto[k:]
    part = automatic_stretch(auto, p.window)
    if part is not None and auto is not None:
        a, b = part.start, part.stop
        pv, op, auto = pv[a:b], op[a:b], auto[a:b]
        sp = None if sp is None else np.asarray(sp, dtype=np.float64)[a:b]
    return _Prepared(pv, op, sp, auto, bool(held.any()), change, part)


def _standard(
    pv: FloatArray,
    op: FloatArray,
    ts: float,
    sp: FloatArray | None = None,
    auto: BoolArray | None = None,
    loop_type: str = "other",
    params: ChainParams | None = None,
    quantify: bool = True,
    exclude_stiction: bool = False,
    baseline: Baseline | None = None,
) -> DiagnosisDraft:
    """Run the standard chain on one window; the draft of its diagnosis.

    The steps: check the window (IM), read the stick-slip events, let the window's own verdict
    stand, find the oscillation (AIM), then judge a quiet loop (tuning, events) or an
    oscillating one (FAM/SAM: the stiction tests' vote, else the tuning/disturbance split).

    Parameters
    ----------
    pv, op, sp:
        Process variable and set point (engineering units), controller output (% 0–100);
        NaN marks a gap. ``sp`` None means a constant set point.
    ts:
        Sample time, s.
    auto:
        True where the loop is in automatic; None means always.
    loop_type:
        One of ``flow``, ``pressure``, ``level``, ``temperature``, ``composition``, ``other``.
    quantify:
        Estimate S and J (Hammerstein identification, ~0.4 s per hour at 1 s) when the cause
        is stiction.
    exclude_stiction:
        The valve is known to be healthy (advanced chain): an oscillation is split between
        tuning and disturbance only.
    baseline:
        The loop's variability in healthy operation (``baseline.Baseline``): a loop whose
        error varies ``DEGRADED_RATIO`` times more is not ``ok``.
    """
    if loop_type not in LOOP_TYPES:
        raise ValueError(f"loop_type must be one of {', '.join(LOOP_TYPES)}, not {loop_type!r}")
    p = params or default_chain_params()
    prep = _prepare(pv, op, sp, auto, ts, p)
    pv, op, sp, auto = prep.pv, prep.op, prep.sp, prep.auto
    change, part = prep.change, prep.part
    win = check_window(pv, op, sp, auto, p.window)
    diag = DiagnosisDraft(
        loop_type=loop_type,
        chain="standard",
        samples=int(pv.size),
        sample_time_s=ts,
        cause="ok",
        confidence=0.0,
        oscillating=False,
        notes=list(win.notes),
    )
    if part is not None:
        # where no mode tag said so, the note says how the manual time was read
        read = " (OP held exactly still while PV kept moving)" if prep.held else ""
        diag.notes.insert(
            0,
            f"{100 * part.manual_share:.1f} % of the window in manual{read}: judged on its "
            f"longest automatic stretch, {part.start * ts:.0f}-{part.stop * ts:.0f} s "
            f"({(part.stop - part.start) * ts:.0f} s)",
        )
    if change is not None:
        diag.notes.insert(0, change_note(change, ts, pv.size))
        diag.controller_change = change_json(change, ts)
    diag.indices["hagglund_load_count"] = None
    diag.indices["idle_index"] = None
    diag.indices["saturation_fraction"] = win.indices.get("saturation_fraction")
    run = _Run(win, ts, loop_type, p, quantify, exclude_stiction, diag, baseline=baseline)
    run = _run_chain(run)
    _with_tuning(run)
    _with_kpis(run)
    return run.diag


def _with_tuning(run: _Run) -> None:
    """The retuning (issue 48) of a loop whose cause is its tuning, or why a valve at fault
    gets none; the action text gains the proposal."""
    diag = run.diag
    out = tuning_for(
        diag.cause, run.win.pv, run.win.op, run.ts, run.loop_type,
        np.asarray(run.win.steps, dtype=np.int64), run.win.indices.get("auto_fraction"),
        run.pi_window, run.p.retuning,
    )  # fmt: skip
    if out is not None:
        diag.tuning = out.json
        if out.action_text and diag.actions:
            diag.actions[0] = {**diag.actions[0], "text": diag.actions[0]["text"] + out.action_text}


def _with_kpis(run: _Run) -> None:
    """The window's performance indices (issue 49), with the dead time the retuning
    identified where none is configured."""
    win, diag = run.win, run.diag
    dead_time, source = dead_time_for(run.p.dead_time_s, diag.tuning)
    diag.kpis = window_kpis(
        win.pv, win.op, win.sp, run.ts,
        auto_share=win.indices.get("auto_fraction"),
        op_limit=win.indices.get("op_limit"),
        op_limit_share=float(win.indices.get("saturation_fraction") or 0.0),
        dead_time_s=dead_time, dead_time_source=source,
        baseline_sd=run.baseline.error_sd if run.baseline is not None else None,
        params=run.p.kpis,
    )  # fmt: skip


def _run_chain(run: _Run, gather: bool = False) -> _Run:
    """The chain's steps on a checked window, then the learned decision where it applies.
    ``gather``: gather the evidence the rules' path did not need even without a model to
    weigh it (``chain_evidence``: the corpus must show the fit what a diagnosis serves)."""
    win, p = run.win, run.p
    if not (_read_events(run) or _window_verdict(run)):
        stretch = run.stretch = _find_oscillation(run)
        if stretch.osc.oscillating:
            _judge_oscillation(run, stretch)
        else:
            _judge_quiet_loop(run, stretch)
    model = p.cause_model if p.cause_model is not None and _within_corpus(run) else None
    if _judged(win) and (gather or model is not None):
        _gather(run)
        if model is not None:
            _weigh(run, model)
    _too_short(run)
    if _judged(win):
        _against_baseline(run)
    return run


def _gather(run: _Run) -> None:
    """The evidence the rules' path did not need (issue 46): the oscillation test on the
    settled stretch of a window the window checks or the stick-slip events decided, and the
    stiction tests wherever a period was found. Run on a scratch draft: the diagnosis keeps
    only what its own path wrote."""
    win, p = run.win, run.p
    if run.stretch is None and win.segment[1] - win.segment[0] >= p.window.min_samples:
        scratch = DiagnosisDraft(run.loop_type, "standard", run.diag.samples, run.ts, "ok", 0.0,
                                 False)  # fmt: skip
        run.stretch = _find_oscillation(replace(run, diag=scratch))
    st = run.stretch
    if st is None or st.osc.period_s is None or run.tests or run.exclude_stiction:
        return
    a, b = st.a, st.b
    run.tests = run_stiction_tests(win.sp[a:b] - win.pv[a:b], win.op[a:b], win.pv[a:b], run.ts,
                                   st.osc, run.loop_type, p, _error_noise(win, st))  # fmt: skip
    if run.decay is None:
        _decay_ratio(run, st)


def _within_corpus(run: _Run) -> bool:
    """Whether the window is of a kind the learned decision was fitted on: OP at an output
    limit for at most ``CLAMP_SUPPORT`` of it. Beyond, the window checks' verdict stands and a
    note says why (the model would read a window unlike any of its corpus)."""
    share = float(run.win.indices.get("saturation_fraction") or 0.0)
    if share <= CLAMP_SUPPORT:
        return True
    if _judged(run.win):
        run.diag.notes.append(
            f"OP at its limit for {100 * share:.0f} % of the window: the learned decision, "
            f"fitted on windows clamped for at most {100 * CLAMP_SUPPORT:.0f} % of their "
            "samples, is not asked"
        )
    return False


def _judged(win: WindowReport) -> bool:
    """Whether the window holds evidence to weigh: usable, saturated, or cut short by
    set-point steps only (not bad data, manual mode or too few samples)."""
    return win.verdict in (None, "saturation") or win.sp_limited


def chain_evidence(
    pv: FloatArray,
    op: FloatArray,
    ts: float,
    sp: FloatArray | None = None,
    auto: BoolArray | None = None,
    loop_type: str = "other",
    params: ChainParams | None = None,
) -> tuple[str, dict[str, float | None] | None]:
    """The rules' cause and the evidence (``evidence.FEATURES``) of one window, None for a
    window with nothing to weigh: what ``plantcheck model fit`` learns from. The rules
    decide here (``params.cause_model`` is ignored) and S/J are not estimated."""
    p = replace(params or default_chain_params(), cause_model=None)
    prep = _prepare(pv, op, sp, auto, ts, p)
    win = check_window(prep.pv, prep.op, prep.sp, prep.auto, p.window)
    diag = DiagnosisDraft(loop_type, "standard", int(prep.pv.size), ts, "ok", 0.0, False)
    run = _run_chain(_Run(win, ts, loop_type, p, False, False, diag), gather=True)
    return diag.cause, (_evidence(run) if _judged(win) else None)


def chain_shape_input(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray | None = None,
    auto: BoolArray | None = None,
    loop_type: str = "other",
    params: ChainParams | None = None,
    *,
    ts: float,
) -> tuple[ShapeInput, bool]:
    """The shape network's input of one window as a diagnosis reads it (the window checks'
    cleaned signals of what ``_prepare`` keeps; ``ts``, s, for its retuning search), and
    whether the window holds evidence to weigh (``chain_evidence`` gives None where it does
    not): what ``plantcheck model fit`` fits the network on."""
    p = params or default_chain_params()
    prep = _prepare(pv, op, sp, auto, ts, p)
    win = check_window(prep.pv, prep.op, prep.sp, prep.auto, p.window)
    return _shape_input(win, loop_type), _judged(win)


def _shape_input(win: WindowReport, loop_type: str) -> ShapeInput:
    """The shape network's input of a checked window, with the noise σ the checks found."""
    return shape_input(win.pv, win.op, win.sp, loop_type, win.error_noise, win.op_noise)


def _read_events(run: _Run) -> bool:
    """Stick-slip events on the whole window (also where set-point steps leave no settled
    stretch); True when they decide the window alone."""
    win, diag = run.win, run.diag
    if win.verdict is not None and not win.sp_limited:
        return False
    # the controller identified on the whole window gives the process gain's sign
    run.pi_window = identify_pi(win.op, win.pv, win.sp, run.ts)
    run.gain_sign = run.pi_window.gain_sign
    fastest = dict(run.p.fast_processes).get(run.loop_type)
    run.events = detect_stick_slip(
        win.pv,
        win.op,
        win.sp,
        is_integrating(run.loop_type),
        run.gain_sign,
        run.p.stick_slip,
        fastest_process=None if fastest is None else fastest / run.ts,
        op_noise=win.op_noise,
        bridged=win.bridged,
    )
    _events_into(diag, run.events, run.ts)
    decides = win.verdict is not None and run.events.test.verdict == "stiction"
    if decides and not run.exclude_stiction:
        # set-point steps hide the oscillation tests, not the events around them
        _stiction_from_events(diag, run.events, win.pv, win.op, run.gain_sign)
        return True
    return False


def _window_verdict(run: _Run) -> bool:
    """The window checks' verdict (data quality, manual mode, saturation, too little left)
    stands; True when there is one."""
    verdict = run.win.verdict
    if verdict is None:
        return False
    if run.win.sp_limited and _judge_steps_alone(run):
        return True
    run.diag.cause = verdict
    run.diag.confidence = 0.9
    run.diag.actions = [action_for(verdict)]
    return True


def _judge_steps_alone(run: _Run) -> bool:
    """Set-point steps too close together for the oscillation tests: their responses judge the
    tuning alone (issue 25 item 1). Slow ones are sluggish; fast, well-damped ones are ok;
    True when they decide. A response that overshoots may be an aggressive controller, a
    sticky valve or a disturbance, which only the oscillation tests tell apart: undecided."""
    win, p, diag = run.win, run.p, run.diag
    responses = sp_step_responses(win.pv, win.sp, np.asarray(win.steps, dtype=np.int64))
    slowness = step_slowness(responses)
    if slowness is None:
        return False
    overshoot = float(np.median([r.overshoot for r in responses]))
    diag.indices["sp_step_slowness"] = slowness
    diag.indices["sp_step_overshoot"] = overshoot
    if slowness > p.tuning.step_slowness_limit:
        diag.cause, diag.confidence = "sluggish_tuning", 0.6
    elif overshoot <= p.tuning.step_overshoot_limit:
        diag.cause, diag.confidence = "ok", 0.5
    else:
        return False
    diag.notes.append(
        f"judged from the {len(responses)} set-point step response(s) alone: closed-loop time "
        f"constant {slowness:.1f} x the dead time (sluggish above "
        f"{p.tuning.step_slowness_limit:g}), overshoot {100 * overshoot:.0f} % (median)"
    )
    diag.actions = [action_for(diag.cause)]
    return True


def _find_oscillation(run: _Run) -> _Stretch:
    """The oscillation test (AIM) on the control error of the settled stretch, then of the
    other settled stretches, then on OP; the controller identified on the stretch read."""
    win, ts, p, diag = run.win, run.ts, run.p, run.diag
    a, b = win.segment
    osc = detect_oscillation(win.sp[a:b] - win.pv[a:b], ts, p.oscillation)
    on_op = False
    if not osc.oscillating:
        # Between set-point steps each settled stretch is a window of its own: a limit cycle
        # that the longest stretch happens to hide (a load change there) shows in another.
        for a2, b2 in win.segments[1:]:
            osc2 = detect_oscillation(win.sp[a2:b2] - win.pv[a2:b2], ts, p.oscillation)
            if osc2.oscillating:
                a, b, osc = a2, b2, osc2
                diag.notes.append(
                    f"the oscillation shows in the settled stretch {a}-{b} ({b - a} samples)"
                )
                break
    pv_s, op_s, sp_s = win.pv[a:b], win.op[a:b], win.sp[a:b]
    whole = (a, b) == (0, diag.samples)
    pi = run.pi_window if whole and run.pi_window is not None else identify_pi(op_s, pv_s, sp_s, ts)
    diag.indices["controller_fit"] = pi.fit
    diag.indices["controller_ti_s"] = pi.ti_s if pi.fit >= p.tuning.pi_min_fit else None
    if not osc.oscillating:
        # A controller that rejects an oscillating load well, or PV noise larger than a small
        # limit cycle, leaves the oscillation visible in OP only.
        osc_op = detect_oscillation(op_s, ts, p.oscillation)
        if osc_op.oscillating:
            diag.notes.append(
                "the oscillation shows in OP (the controller output cycles) more than in PV"
            )
            osc, on_op = osc_op, True
    diag.indices["hagglund_load_count"] = osc.load_count
    diag.oscillating = osc.oscillating
    return _Stretch(a, b, osc, pi, on_op)


def _judge_quiet_loop(run: _Run, st: _Stretch) -> None:
    """A loop without sustained oscillation: sluggish tuning from its set-point step
    responses or its idle index (Hägglund), or stiction from its stick-slip events, or ok."""
    win, ts, p, diag, events = run.win, run.ts, run.p, run.diag, run.events
    pv_s, op_s, sp_s = win.pv[st.a : st.b], win.op[st.a : st.b], win.sp[st.a : st.b]
    pi = st.pi
    diag.notes.append(f"no sustained oscillation: {st.osc.reason}")
    ti = pi.ti_s if (pi.ti_s and pi.fit >= p.tuning.pi_min_fit) else None
    tf = idle_filter_s(sp_s - pv_s, ts, ti, p.tuning)
    # The idle index assumes a self-regulating process: an integrating loop always needs
    # OP to overshoot to bring the level back, so the index is negative whatever the tuning.
    ii = (
        None
        if is_integrating(run.loop_type)
        else idle_index(op_s, pv_s, ts, pi.gain_sign, tf, p.tuning)
    )
    diag.indices["idle_index"] = ii
    idle_sluggish = ii is not None and ii > p.tuning.idle_limit
    sluggish = idle_sluggish
    steps = np.asarray(win.steps, dtype=np.int64)
    responses = sp_step_responses(
        win.pv, win.sp, steps, op=win.op, gain_sign=run.gain_sign,
        jump_horizon=p.stick_slip.jump_horizon,
    )  # fmt: skip
    slowness = step_slowness(responses)
    diag.indices["sp_step_slowness"] = slowness
    recoveries = () if is_integrating(run.loop_type) else load_recoveries(win.pv, win.sp, steps)
    load_slowness = recovery_slowness(recoveries)
    diag.indices["load_recovery_slowness"] = load_slowness
    slow_recovery = load_slowness is not None and load_slowness > p.tuning.load_recovery_limit
    if slow_recovery and slowness is None:
        # a load step is the experiment a running plant does: an error that comes back many
        # times slower than it went out is sluggish, whatever the idle index reads from the
        # signs of increments that noise swamps in a slow loop
        sluggish = True
        diag.notes.append(
            f"load recoveries: {load_slowness:.1f} x slower than the departures (median of "
            f"{len(recoveries)}; sluggish above {p.tuning.load_recovery_limit:g})"
        )
    if slowness is not None:
        # a set-point step is a clean experiment: it overrules the idle index, which only
        # sees load recoveries and reads a healthy slow loop's creep as sluggish
        sluggish = slowness > p.tuning.step_slowness_limit
        diag.notes.append(
            f"set-point step response(s): closed-loop time constant {slowness:.1f} x the "
            f"dead time (median of {len(responses)}; sluggish above "
            f"{p.tuning.step_slowness_limit:g})" + _fitted_note(responses)
        )
    if events is not None and events.test.verdict == "stiction" and not run.exclude_stiction:
        # A sluggish loop creeps toward SP with OP and PV together (idle index > 0); a load
        # change toward SP then looks like a slip. A sticky valve holds the PV while OP
        # moves and slips against it (index <= 0), unless it does not move at all. Between
        # set-point steps the index reads the tail of a step response, which creeps toward
        # SP in any loop: there it cannot overrule the events, but the step responses can,
        # when every one of them is a sluggish PI's creep and no event slips inside one (a
        # sticky valve under a sluggish controller slips on its way to the new SP).
        creeps = all_creep(
            responses, p.tuning.step_slowness_limit, p.tuning.creep_max_jump
        ) and not _slips_during(events, responses)
        aside = (idle_sluggish and not win.steps) or creeps
        if not aside or events.unresponsive is not None:
            _stiction_from_events(diag, events, win.pv, win.op, run.gain_sign)
            return
        diag.notes.append(
            "stick-slip events set aside: the loop recovers like a sluggish one "
            + (
                f"(every set-point step answered with a creep, {len(responses)} of them)"
                if creeps
                else f"(idle index {ii:.2f})"
            )
        )
    if sluggish and slowness is not None:
        diag.cause = "sluggish_tuning"
        diag.confidence = float(min(0.9, 0.5 + 0.05 * slowness))
    elif sluggish and slow_recovery and load_slowness is not None:
        diag.cause = "sluggish_tuning"
        diag.confidence = float(min(0.9, 0.5 + 0.05 * load_slowness))
    elif sluggish and ii is not None:
        diag.cause = "sluggish_tuning"
        diag.confidence = float(min(0.9, 0.5 + (ii - p.tuning.idle_limit)))
    else:
        diag.cause = "ok"
        diag.confidence = 0.7 if ii is not None else 0.6
    diag.actions = [action_for(diag.cause)]


def _fitted_note(responses: tuple[StepResponse, ...]) -> str:
    """Says when the responses were read by the least-squares fit (steps within 6 noise σ)."""
    if responses and all(r.fitted for r in responses):
        return "; steps of 3-6 x the PV noise, read by a least-squares fit of every sample"
    return ""


def _error_noise(win: WindowReport, st: _Stretch) -> float | None:
    """The window checks' noise σ of SP − PV where the stretch is the whole window."""
    return win.error_noise if (st.a, st.b) == (0, win.pv.size) else None


def _slips_during(events: StickSlipResult, responses: tuple[StepResponse, ...]) -> bool:
    """True when a stick-slip event breaks away while the PV is settling after a set-point
    step (between the step and three closed-loop time constants after its dead time)."""
    spans = [r.settling for r in responses]
    return any(lo <= ev.breakaway <= hi for ev in events.events for lo, hi in spans)


def _judge_oscillation(run: _Run, st: _Stretch) -> None:
    """An oscillating loop (FAM/SAM): the applicable stiction tests and their vote, with the
    stick-slip events beside them; stiction is quantified, any other oscillation split
    between aggressive tuning and an external disturbance (``cause_split``). A cycle at the
    loop's own frequency that dies out within a cycle is no tuning fault: the loop is judged
    as a quiet one (``_well_damped``)."""
    win, ts, p, diag, events, osc = run.win, run.ts, run.p, run.diag, run.events, st.osc
    pv_s, op_s, sp_s = win.pv[st.a : st.b], win.op[st.a : st.b], win.sp[st.a : st.b]
    if run.exclude_stiction:
        no_stiction = VoteResult("no_stiction", 0, 0, 0, -1.0)
        split = split_cause(op_s, pv_s, ts, osc, {}, no_stiction, st.pi, run.loop_type, p.split)
        if _well_damped(run, st, split, _decay_ratio(run, st)):
            return
        _oscillation_into(diag, osc)
        diag.cause, diag.confidence = split.cause, split.confidence
        diag.notes.append(split.reason + " (valve healthy: stiction excluded)")
        diag.actions = [action_for(diag.cause)]
        return
    tests = run.tests = run_stiction_tests(
        sp_s - pv_s, op_s, pv_s, ts, osc, run.loop_type, p, _error_noise(win, st)
    )
    if events is not None:
        tests["stick_slip"] = _events_vote(events, p.stick_slip)
    v = vote(list(tests.values()), p.vote)
    alone = None
    if v.decision != "stiction":
        ratio = _decay_ratio(run, st)
        sustained = ratio is not None and ratio >= p.split.min_decay_ratio
        alone = curve_fit_decides(list(tests.values()), sustained, p.vote)
        if alone is not None:
            v = replace(v, decision="stiction")
        else:
            split = split_cause(op_s, pv_s, ts, osc, tests, v, st.pi, run.loop_type, p.split)
            if _well_damped(run, st, split, ratio):
                return
    _oscillation_into(diag, osc)
    diag.stiction["tests"] = _tests_json(tests)
    diag.stiction["votes"] = {name: r.verdict for name, r in tests.items()}
    diag.stiction["vote"] = {
        "decision": v.decision,
        "for": v.n_stiction,
        "against": v.n_no_stiction,
        "tests": v.n_tests,
    }
    diag.stiction["detected"] = v.decision == "stiction"
    diag.indices["stiction_vote"] = v.score
    if v.decision == "stiction":
        diag.cause = "stiction"
        diag.confidence = _confidence_from_vote(v, True)
        if alone is not None and alone.value is not None:
            diag.notes.append(
                f"stiction: the curve fit's index {alone.value:.2f} (at least "
                f"{p.vote.curve_fit_alone:g}, He et al. 2007) on a sustained cycle decides "
                f"alone ({v.n_stiction} of {v.n_tests} tests say stiction, none of the "
                "waveform tests says no)"
            )
        else:
            diag.notes.append(f"stiction: {v.n_stiction} of {v.n_tests} tests agree")
        if run.quantify:
            _quantify_into(diag, op_s, pv_s, ts, osc, p)
        if events is not None:
            _estimate_into(diag, events, win.pv, win.op, run.gain_sign)
    else:
        diag.cause = split.cause
        diag.confidence = split.confidence
        diag.notes.append(split.reason)
    diag.actions = [_stiction_action(diag)]


def _oscillation_into(diag: DiagnosisDraft, osc: OscillationResult) -> None:
    diag.oscillation = {
        "period_s": osc.period_s,
        "amplitude": osc.amplitude,
        "regularity": osc.regularity,
    }
    diag.oscillations = oscillations_json(osc)


DAMPED_CAUSES = frozenset({"aggressive_tuning", "oscillation_unknown_cause"})
"""The split's verdicts that a well damped cycle overrules (``_well_damped``): generated
healthy loops read as either had R 0.14-0.48. The disturbances read as external mostly have
0.9 and above, but 16 of the generated ones (the matrix, and the plant windows on three process
tables) have less than 0.5: there the ACF is not asked."""


def _decay_ratio(run: _Run, st: _Stretch) -> float | None:
    """Miao & Seborg's ACF decay ratio of the cycle read: the control error's over the
    stretch, or OP's where the cycle showed in OP. Read once per window: the curve fit's
    sustained-cycle check and ``_well_damped`` both use it."""
    win = run.win
    x = win.op[st.a : st.b] if st.on_op else win.sp[st.a : st.b] - win.pv[st.a : st.b]
    run.decay = acf_decay_ratio(x)
    return run.decay


def _well_damped(run: _Run, st: _Stretch, split: SplitResult, ratio: float | None) -> bool:
    """Where the split reads the cycle as the loop's own (or cannot tie it to anything),
    whether the loop rings on or damps it out: a decay ratio of the ACF below
    ``SplitParams.min_decay_ratio`` (Miao & Seborg 1999) is a well damped loop whose noise and
    loads excite its own frequency, as any fast loop's do (a SIMC-tuned loop with a dead time
    of one or two samples shows a spectral bump that the regularity test can take for an
    oscillation). Such a loop is judged as a quiet one (tuning, stick-slip events, or ok), with
    the reason in the notes. A disturbance the split reads as external keeps its verdict: a
    periodic load is sustained, whatever its ACF says through the loop's own noise. ``ratio``:
    ``_decay_ratio`` of the stretch."""
    if split.cause not in DAMPED_CAUSES:
        return False
    p = run.p
    if ratio is None or ratio >= p.split.min_decay_ratio:
        return False
    run.diag.oscillating = False
    where = "at the loop's own frequency " if split.cause == "aggressive_tuning" else ""
    reason = (
        f"the cycle {where}({st.osc.period_s:.0f} s) is well damped "
        f"(ACF decay ratio {ratio:.2f} < {p.split.min_decay_ratio:g}, Miao & Seborg 1999)"
    )
    _judge_quiet_loop(run, replace(st, osc=replace(st.osc, oscillating=False, reason=reason)))
    return True


def diagnose(
    pv: FloatArray,
    op: FloatArray,
    ts: float,
    sp: FloatArray | None = None,
    auto: BoolArray | None = None,
    loop_type: str = "other",
    params: ChainParams | None = None,
    quantify: bool = True,
    exclude_stiction: bool = False,
    baseline: Baseline | None = None,
) -> Diagnosis:
    """Run the standard chain on one window (arguments: ``_standard``): the frozen diagnosis."""
    return _standard(
        pv, op, ts, sp, auto, loop_type, params, quantify, exclude_stiction, baseline
    ).freeze()


def _events_vote(res: StickSlipResult, params: StickSlipParams) -> StictionTestResult:
    """The stick-slip test as a vote beside the oscillation-based tests: an oscillating loop
    (aggressive tuning, a periodic disturbance) turns OP at every half-cycle and gives a few
    events by accident, so there it votes ``stiction`` only with ``oscillating_strong_events``
    events confirmed by the valve-step model (or a valve that does not respond)."""
    n_strong = sum(ev.strong for ev in res.events)
    if res.unresponsive is not None or n_strong >= params.oscillating_strong_events:
        return res.test
    return replace(res.test, verdict="undecided")


def _events_into(diag: DiagnosisDraft, res: StickSlipResult, ts: float) -> None:
    """The optional ``stiction.events`` (contracts §2): times in s from the window's first
    sample, OP travel in %, PV jump in PV units."""
    if res.events:
        diag.stiction["events"] = [
            {
                "start": ev.start * ts,
                "end": ev.end * ts,
                "op_travel": ev.op_travel,
                "pv_jump": ev.pv_jump,
            }
            for ev in res.events
        ]


def _stiction_from_events(
    diag: DiagnosisDraft, res: StickSlipResult, pv: FloatArray, op: FloatArray, gain_sign: int
) -> None:
    """Cause ``stiction`` from stick-slip events alone (no sustained oscillation needed).

    Confidence grows with the events the valve-step model confirms: 0.6 for one, up to 0.85;
    0.55 for fast events alone; 0.7 for a valve that does not respond at all.
    """
    n_strong = sum(ev.strong for ev in res.events)
    diag.cause = "stiction"
    diag.stiction["detected"] = True
    diag.stiction["tests"] = {"stick_slip": res.test.value}
    diag.stiction["votes"] = {"stick_slip": res.test.verdict}
    if res.unresponsive is not None:
        diag.confidence = 0.7
        diag.notes.append(res.unresponsive)
        diag.notes.append(
            "no size: the valve did not move in the window (seized, shut against its seat, or "
            "the line is blocked); check it on site"
        )
    else:
        diag.confidence = min(0.85, 0.5 + 0.1 * n_strong) if n_strong else 0.55
        diag.notes.append("stiction from stick-slip events: " + res.test.detail)
        _estimate_into(diag, res, pv, op, gain_sign)
    diag.actions = [_stiction_action(diag)]


def _estimate_into(
    diag: DiagnosisDraft, res: StickSlipResult, pv: FloatArray, op: FloatArray, gain_sign: int
) -> None:
    """The optional ``stiction.estimate``: the best size available (contracts §2).

    A reliable Hammerstein estimate (methods §6.1) first; else the events' stickband (Kano et
    al. 2004: median OP travel at breakaway) and slip (median PV jump through the process gain);
    else the apparent stiction of the PV(OP) ellipse (§6.2), which ranks valves but is not S.
    """
    st = diag.stiction
    if st.get("S") is not None and (st.get("quantification") or {}).get("reliable"):
        st["estimate"] = {"S": st["S"], "J": st.get("J"), "method": "hammerstein", "reliable": True}
        return
    size = size_from_events(res, pv, op, gain_sign)
    if size is not None:
        st["estimate"] = {"S": size.S, "J": size.J, "method": "events", "reliable": size.reliable}
        if size.reason:
            diag.notes.append(f"S from the stick-slip events, not reliable: {size.reason}")
        return
    if st.get("apparent") is not None:
        st["estimate"] = {"S": st["apparent"], "J": None, "method": "ellipse", "reliable": False}


def _stiction_action(diag: DiagnosisDraft) -> dict[str, str]:
    """The suggested action, sized by the best estimate and naming its method when that is
    not the Hammerstein identification."""
    est = diag.stiction.get("estimate") or {}
    if diag.cause == "stiction" and est.get("S") is not None:
        return action_for(diag.cause, est["S"], est.get("J"), est.get("method"))
    return action_for(diag.cause, diag.stiction.get("S"), diag.stiction.get("J"))


def _quantify_recent(
    diag: DiagnosisDraft,
    op: FloatArray,
    pv: FloatArray,
    ts: float,
    period_s: float | None,
    p: ChainParams,
) -> QuantificationResult:
    """Hammerstein S/J estimate (methods §6.1) on the most recent part of the window.

    Friction is constant within a window and a few tens of cycles identify it: the last
    max(3,600 samples, 40 periods) are used, so that day-long windows stay fast.
    """
    period_samples = (period_s or 0.0) / ts
    keep = int(max(p.quantification.min_window, p.quantification.window_periods * period_samples))
    if op.size > keep:
        op, pv = op[-keep:], pv[-keep:]
        diag.notes.append(f"S and J estimated on the last {keep} samples of the window")
    integrating = is_integrating(diag.loop_type)
    # imported here: a window that is not sized (most) needs none of its grids and filters
    from plantcheck.diagnosis.quantification import quantify_stiction

    return quantify_stiction(op, pv, ts, period_s, p.quantification, integrating)


def _filtered_note(
    cycle_s: float | None, detected_s: float | None, external_s: float | None
) -> str:
    """The cycle the quantification used and what it filtered out, for its note (s)."""
    parts = []
    if cycle_s and detected_s and cycle_s != detected_s:
        parts.append(
            f"on the valve's own {cycle_s:.0f} s cycle, found beneath the detected "
            f"{detected_s:.0f} s oscillation"
        )
    if external_s:
        parts.append(f"an external oscillation of period {external_s:.0f} s filtered out")
    return f" ({'; '.join(parts)})" if parts else ""


def _quantify_into(
    diag: DiagnosisDraft,
    op: FloatArray,
    pv: FloatArray,
    ts: float,
    osc: OscillationResult,
    p: ChainParams,
) -> None:
    """Fill stiction.S/J (% of valve travel) when the Hammerstein estimate is reliable
    (methods §6.1), else leave them null and say why; add the apparent stiction (§6.2)."""
    q = _quantify_recent(diag, op, pv, ts, osc.period_s, p)
    diag.stiction["S"] = q.S
    diag.stiction["J"] = q.J
    diag.stiction["quantification"] = {
        "reliable": q.reliable,
        "model": q.model,
        "fit_percent": q.fit,
        "S_best": q.S_best,
        "J_best": q.J_best,
        "reasons": q.reasons,
        "reason_codes": q.reason_codes,
        "external_period_s": q.external_period_s,
        "period_s": q.period_s,
    }
    # the valve's own cycle: a faster oscillation found beneath the detected one, if any
    cycle_s = q.period_s or osc.period_s
    ell = apparent_stiction(op, pv, ts, cycle_s) if cycle_s else None
    diag.stiction["apparent"] = ell.apparent_stiction if ell is not None else None
    if q.reliable:
        diag.notes.append(
            f"stiction quantified ({q.model} model, fit {q.fit:.0f} %): "
            f"S = {q.S_best:.2f} %, J = {q.J_best:.2f} % of valve travel"
            + _filtered_note(q.period_s, osc.period_s, q.external_period_s)
        )
    else:
        diag.notes.append("S and J not reported: " + "; ".join(q.reasons))


def _evidence(run: _Run) -> dict[str, float | None]:
    """The window's evidence (``evidence.FEATURES``): what the chain computed on it."""
    win, diag = run.win, run.diag
    integrating = is_integrating(run.loop_type)
    ev: dict[str, float | None] = dict(
        window_evidence(
            win.pv, win.op, win.sp, win.indices, integrating, win.error_noise, win.op_noise
        )
    )
    ind = diag.indices
    for name in ("idle_index", "sp_step_slowness", "sp_step_overshoot", "load_recovery_slowness",
                 "controller_fit"):  # fmt: skip
        ev[name] = ind.get(name)
    ev["load_count"] = ind.get("hagglund_load_count")
    ev["vote_score"] = ind.get("stiction_vote")
    if ev["vote_score"] is None and run.tests:
        ev["vote_score"] = vote(list(run.tests.values()), run.p.vote).score
    ev["decay_ratio"] = run.decay
    st = run.stretch
    if st is not None:
        osc = st.osc
        ev["oscillating"] = float(osc.oscillating)
        ev["on_op"] = float(st.on_op)
        ev["regularity"] = osc.regularity
        if osc.period_s:
            period = osc.period_s / run.ts
            ev["log_period_samples"] = float(np.log10(period))
            ev["log_cycles"] = float(np.log10(max(st.b - st.a, 1) / period))
            if st.pi.ti_s and st.pi.fit >= run.p.tuning.pi_min_fit:
                ev["period_over_ti"] = osc.period_s / st.pi.ti_s
        if osc.amplitude is not None and osc.noise_sigma > 0:
            ev["amplitude_noise"] = osc.amplitude / osc.noise_sigma
    e = win.sp - win.pv
    # the error's spectrum, read by both when the analysed stretch is the whole window
    error = SignalSpectrum.of(detrend(e)) if e.size >= 8 else None
    if st is not None and st.b - st.a > 8:
        pi = st.pi if st.pi.fit >= run.p.tuning.pi_min_fit else None
        ti = pi.ti_s / run.ts if pi is not None and pi.ti_s else None
        ev.update(
            shape_evidence(
                win.pv[st.a : st.b],
                win.op[st.a : st.b],
                win.sp[st.a : st.b],
                pi.kc if pi is not None else None,
                ti,
                error if (st.a, st.b) == (0, e.size) else None,
            )
        )
    whole = run.pi_window
    ti_whole = whole.ti_s / run.ts if whole is not None and whole.ti_s else None
    ev.update(spectral_evidence(e, ti_whole))
    ev.update(correlation_evidence(e, win.op, error))
    proc = quick_process_fit(win.pv, win.op, integrating=integrating)
    if proc is not None:
        pi_ok = whole if whole is not None and whole.fit >= run.p.tuning.pi_min_fit else None
        ev.update(
            process_evidence(
                proc.K,
                proc.tau,
                proc.theta,
                proc.fit,
                pi_ok.kc if pi_ok is not None else None,
                ti_whole if pi_ok is not None else None,
                integrating,
            )
        )
    for name, res in run.tests.items():
        if name in FEATURE_TESTS:
            ev[name] = res.value
    events = run.events
    if events is not None:
        ev["stick_slip"] = events.test.value
        ev["events"] = float(len(events.events))
        ev["strong_events"] = float(sum(e.strong for e in events.events))
        ev["event_reversals"] = float(events.reversals)
        ev["event_travel"] = events.travel_median
        ev["unresponsive"] = float(events.unresponsive is not None)
    return ev


FEATURE_TESTS = frozenset(
    {"relay", "curve_fit", "area_ratio", "bicoherence", "cross_correlation", "histogram"}
)
"""The stiction tests whose values enter the evidence by their own names."""

TOP_EVIDENCE = 5
"""How many inputs the JSON's ``evidence`` lists."""


def _weigh(run: _Run, model: CauseModel) -> None:
    """The calibrated model weighs the evidence the chain gathered (issue 46): each cause's
    probability and the inputs that moved it most. With ``decide_by = "learned"`` the most
    probable cause is the verdict (a sticky valve's size read where the rules named none);
    with ``"rules"`` the rules' verdict stands, its confidence is the model's probability of
    it, and a note names the cause the model prefers when they differ."""
    diag, p = run.diag, run.p
    ev = _evidence(run)
    shape = None
    if model.shape is not None:
        shape = _shape_input(run.win, run.loop_type)
    d = decide(model, evidence_vector(ev), shape)
    probs = d.probabilities.copy()
    if run.exclude_stiction and "stiction" in model.classes:
        probs[model.classes.index("stiction")] = 0.0
        probs /= probs.sum()
    best = int(np.argmax(probs))
    rules = diag.cause
    learned = p.decide_by == "learned"
    if not learned and rules not in model.classes:
        return
    k = best if learned else model.classes.index(rules)
    diag.probabilities = {c: round(float(v), 3) for c, v in zip(model.classes, probs, strict=True)}
    diag.evidence = _moved_most(model, d, ev, k)
    diag.confidence = float(probs[k])
    if not learned:
        if best != k:
            diag.notes.append(
                f"the learned decision reads {model.classes[best]} (p = {probs[best]:.2f}); the "
                f"rules' {rules} has p = {probs[k]:.2f}"
            )
        return
    cause = model.classes[k]
    if cause != rules:
        diag.notes.append(
            f"the learned decision reads {cause} (p = {probs[k]:.2f}) where the rules read {rules}"
        )
    diag.cause = cause
    diag.stiction["detected"] = cause == "stiction"
    if cause == "stiction" and run.events is not None and "estimate" not in diag.stiction:
        _estimate_into(diag, run.events, run.win.pv, run.win.op, run.gain_sign)
    diag.actions = [_stiction_action(diag)]


def _moved_most(
    model: CauseModel, d: Decision, ev: dict[str, float | None], k: int
) -> list[dict[str, object]]:
    """The ``TOP_EVIDENCE`` inputs that moved class ``k`` most. With a shape network blended
    in, each tree input's contribution is scaled into the blend's log-odds, (1 − w) / (T·T₂)
    times its share of the raw score, beside the network's own: w / T₂ times its log-probability
    of the class less what it gives an average window (``shape_base``; its ``value``: its
    probability of the class)."""
    names = list(model.features)
    values: list[float | None] = [ev.get(n) for n in names]  # rounded for the few listed
    moves = d.contributions[k].copy()
    if d.shape_probabilities is not None:
        moves *= (1.0 - model.shape_weight) / (model.temperature * model.blend_temperature)
        log_shape = safe_log(d.shape_probabilities)
        base = (
            np.asarray(model.shape_base)
            if model.shape_base
            else np.full(log_shape.size, log_shape.mean())
        )
        names.append(SHAPE_EVIDENCE)
        values.append(float(d.shape_probabilities[k]))
        moves = np.append(
            moves,
            model.shape_weight / model.blend_temperature * (log_shape[k] - base[k]),
        )
    order = np.argsort(-np.abs(moves))[:TOP_EVIDENCE]
    return [
        {"name": names[i], "value": _rounded(values[i]), "contribution": round(float(moves[i]), 3)}
        for i in order.tolist()
        if moves[i] != 0.0
    ]


SHAPE_EVIDENCE = "signal_shape"
"""The shape network's name among the evidence: its value is its probability of the cause."""


def _against_baseline(run: _Run) -> None:
    """The window's variability (``indices.error_std``, ``op_std``), and against the loop's
    baseline (``variability_ratio``): an ``ok`` far from its own normal takes the cause the
    model finds most probable after ``ok`` when that has p >= ``DEGRADED_MIN_P``, else
    ``performance_degraded`` (issue 46 item 5)."""
    win, diag = run.win, run.diag
    e_sd, op_sd = variability(win.pv, win.op, win.sp)
    diag.indices["error_std"] = e_sd
    diag.indices["op_std"] = op_sd
    if run.baseline is None:
        return
    ratio = e_sd / run.baseline.error_sd
    diag.indices["variability_ratio"] = ratio
    if diag.cause != "ok" or not ratio >= DEGRADED_RATIO:
        return
    note = (
        f"the error varies {ratio:.1f} x its baseline (σ {e_sd:.3g} against "
        f"{run.baseline.error_sd:.3g}{', ' + run.baseline.source if run.baseline.source else ''}"
        f"; far from normal at {DEGRADED_RATIO:g} x)"
    )
    probs = dict(diag.probabilities or {})
    probs.pop("ok", None)
    best = max(probs, key=lambda c: probs[c]) if probs else None
    if best is not None and probs[best] >= DEGRADED_MIN_P:
        diag.cause, diag.confidence = best, probs[best]
        diag.notes.append(f"{note}: read as {best}, the most probable cause after ok")
        diag.stiction["detected"] = best == "stiction"
        diag.actions = [_stiction_action(diag)]
        return
    diag.cause, diag.confidence = "performance_degraded", 0.6
    diag.probabilities = diag.evidence = None
    diag.notes.append(f"{note}, and no test names a cause")
    action = action_for("performance_degraded")
    action["text"] = action["text"].replace("far more", f"{ratio:.1f} times more")
    diag.actions = [action]


DEGRADED_MIN_P = 0.2
"""A loop far from its baseline takes the model's next cause only when it is this probable."""


def _rounded(x: float | None) -> float | None:
    """An evidence value to 4 significant digits (what the tests' indices can mean)."""
    return None if x is None or not np.isfinite(x) else float(f"{x:.4g}")


def _too_short(run: _Run) -> None:
    """A window too short to show a slow fault is no evidence that the loop is healthy
    (issue 46 item 4): ``ok`` on fewer than ``WindowParams.min_segment_samples`` samples reads
    ``insufficient_data`` with the number needed."""
    diag = run.diag
    needed = run.p.window.min_segment_samples
    if diag.cause == "ok" and diag.samples < needed:
        diag.cause, diag.confidence = "insufficient_data", 0.9
        diag.probabilities = diag.evidence = None
        diag.notes.append(
            f"too short to judge: {diag.samples} samples, at least {needed} needed to call the "
            "loop healthy"
        )
        diag.actions = [action_for("insufficient_data")]


WINDOW_VERDICTS = frozenset({"data_quality", "manual_mode", "insufficient_data"})


def diagnose_advanced(
    pv: FloatArray,
    op: FloatArray,
    mv: FloatArray,
    ts: float,
    sp: FloatArray | None = None,
    auto: BoolArray | None = None,
    loop_type: str = "other",
    params: ChainParams | None = None,
    quantify: bool = True,
    baseline: Baseline | None = None,
) -> Diagnosis:
    """The advanced chain (methods.md §7.4): the valve first, from OP and the stem position MV.

    A faulty actuator is the primary verdict (its class is the cause; S and J of a sticky valve
    are measured from MV(OP)). With a healthy valve an oscillating loop is judged for tuning or
    disturbance with stiction excluded. MV in % of travel, NaN = gap.

    The OP/PV stiction tests are not run: MV answers the valve question directly, and the
    loop-level pass only checks the window, finds the oscillation and splits its cause.
    """
    p = params or default_chain_params()
    standard = _standard(
        pv, op, ts, sp, auto, loop_type, p, quantify=False, exclude_stiction=True, baseline=baseline
    )
    standard.chain = "advanced"
    if standard.cause in WINDOW_VERDICTS:
        standard.notes.append("valve not assessed: the window cannot be judged")
        return standard.freeze()
    op_f, _ = fill_short_gaps(np.asarray(op, dtype=np.float64), p.window.max_fill_gap)
    mv_arr = np.asarray(mv, dtype=np.float64)
    if float(np.mean(~np.isfinite(mv_arr))) > p.window.max_missing_fraction:
        standard.notes.append(
            "MV has too many gaps: valve not assessed, standard chain verdict kept"
        )
        return standard.freeze()
    mv_f, _ = fill_short_gaps(mv_arr, p.window.max_fill_gap)
    stem = travel(mv_f, ts, p.kpis.deadband)
    if stem is not None and standard.kpis is not None:
        standard.kpis["mv_travel_per_day"] = round(stem.travel_per_day, 1)
        standard.kpis["mv_reversals_per_day"] = round(stem.reversals_per_day, 1)
    va = classify_valve(op_f, mv_f, ts, p.valve)
    standard.valve = {
        "state": va.state if va.state != "data_quality" else "unknown",
        "kpis": va.kpis,
    }
    standard.notes.extend(va.reasons)
    if va.state == "data_quality":
        standard.notes.append("MV unusable (flat while OP moves): check the position feedback")
        return standard.freeze()
    if va.state != "ok":
        standard.cause = va.state
        standard.confidence = 0.8
        standard.tuning = valve_first(va.state).json
        standard.stiction["detected"] = va.state == "stiction"
        if va.state in ("stiction", "deadband_backlash"):
            standard.stiction["S"] = va.S
            standard.stiction["J"] = va.J
            standard.stiction["source"] = "mv"
            if quantify and standard.oscillation is not None:
                # the OP/PV-only estimate beside the measured one (methods §7.4 step 4)
                pv_f, _ = fill_short_gaps(np.asarray(pv, dtype=np.float64), p.window.max_fill_gap)
                q = _quantify_recent(standard, op_f, pv_f, ts, standard.oscillation["period_s"], p)
                standard.stiction["op_pv_estimate"] = {"S": q.S, "J": q.J, "reliable": q.reliable}
        standard.actions = [
            action_for(standard.cause, standard.stiction.get("S"), standard.stiction.get("J"))
        ]
        return standard.freeze()
    standard.stiction["detected"] = False
    return standard.freeze()
