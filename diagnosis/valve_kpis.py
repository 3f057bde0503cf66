"""Actuator KPIs from the valve position error e_v = OP − MV (methods.md §7.2) and the actuator
classification (§7.3). A reconstruction of the PCU advanced chain (Bacci di Capaci, Scali et al.
2013; thesis ch. 6): every limit is a parameter, calibrated on the generated actuator cases.

OP and MV in % of travel, times in seconds. The OP–MV delay is removed first (cross-correlation
of the increments), then:

- bias μ_v, dispersion σ_v, 99th percentile of |e_v|;
- linear fit MV = a + b·OP (gain and offset errors of the positioner calibration);
- stuck episodes: MV still while OP travels; their OP travel before a breakaway after a reversal
  estimates the stickband S_v, the MV jump at breakaway the slip J_v (Kano et al. 2004);
- MV-only oscillation (hunting): power MV has in a frequency band where OP has little;
- drift of e_v over the window (%/h): air leakage pulls the stem toward the fail position;
- rate limit: MV speed saturating at its maximum while e_v is large (undersized actuator).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from plantcheck.diagnosis.signal_tools import (
    FloatArray,
    fft_ccf,
    first_order_lag,
    moving_average,
    noise_sigma,
)

VALVE_STATES = (
    "ok",
    "stiction",
    "deadband_backlash",
    "positioner_fault",
    "positioner_tuning",
    "air_leakage",
    "actuator_undersized",
)


@dataclass(frozen=True)
class ValveParams:
    """Limits of the actuator classification [R, calibrated on generated actuator cases]."""

    max_delay_s: float = 10.0
    """Largest OP→MV delay searched, s."""
    resolution: float = 0.05
    """Smallest MV (and OP) movement that counts, % of travel (positioner resolution)."""
    stuck_min_travel: float = 0.25
    """A stuck episode needs at least this OP travel (% of travel) while MV stays still."""
    stuck_fraction: float = 0.2
    """f_st above this (with S_v above min_stickband) -> friction fault (§7.3)."""
    min_stickband: float = 0.4
    """S_v (% of travel) needed for a friction verdict (§7.3 uses 0.5 %)."""
    op_smooth_noise: float = 0.1
    """OP is averaged over as many samples as bring its noise to this (% of travel) before the
    stuck-episode scan, so that dither around a deadband does not hide the OP travel."""
    slip_s: float = 2.0
    """Longest MV slip after a breakaway, s (a positioner spreads the jump over its lag)."""
    slip_ratio: float = 0.25
    """J_v > this × S_v -> stiction; below -> deadband/backlash (§7.3)."""
    bias_limit: float = 1.0
    """|μ_v| above this (% of travel) -> calibration fault (§7.3)."""
    gain_limit: float = 0.05
    """|b − 1| above this -> span (gain) fault, when OP spans at least ``gain_min_span``."""
    gain_min_span: float = 5.0
    """OP range (% of travel) needed to judge the gain."""
    drift_limit: float = 1.0
    """|d μ_v/dt| above this (% of travel per hour) -> air leakage."""
    drift_share: float = 0.5
    """... and the drift explains at least this share of the e_v variance."""
    hunting_amplitude: float = 0.25
    """MV-only oscillation amplitude (% of travel) above which the positioner hunts."""
    hunting_ratio: float = 3.0
    """... where MV has at least this many times OP's power in the band: MV is the source (a
    lagging or miscalibrated positioner follows OP with a power ratio near or below 1, a sticky
    valve's square wave reaches ~2 at its harmonics)."""
    spectrum_segment: int = 256
    """Welch segment (samples) of the MV and OP spectra for the hunting KPI."""
    rate_share: float = 0.02
    """Share of samples at the MV speed limit (with a large e_v) -> undersized actuator."""
    rate_error: float = 1.0
    """|e_v| (% of travel) that counts as large while MV moves at its limit."""
    lag_grid_s: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
    """Positioner time constants tried (s) besides none, for the calibration and drift fits."""
    smooth_s: float = 3.0
    """OP and MV are smoothed over this many seconds before the gain/drift regression."""
    speed_window_s: float = 2.0
    """MV speed is measured over this many seconds (rate-limit KPI)."""
    speed_saturation: float = 3.0
    """Undersized when |speed| varies this many times less than |speed|/|e_v| (rate limit,
    not a lag) [R]."""
    calibration_scatter: float = 0.5
    """A calibration fault is a steady map: MV − (a + b·OP) scatters less than this (%)."""


@dataclass(frozen=True)
class ValveAssessment:
    """Actuator state, the KPIs behind it, and the directly measured S_v, J_v (% travel)."""

    state: str
    kpis: dict[str, float | int | None]
    S: float | None
    J: float | None
    reasons: list[str] = field(default_factory=list)


def op_mv_delay(op: FloatArray, mv: FloatArray, ts: float, max_delay_s: float) -> int:
    """Delay (samples) of MV behind OP, from the peak of the increments' cross-correlation."""
    max_lag = max(1, min(int(max_delay_s / ts), op.size // 4))
    lags, c = fft_ccf(np.diff(op), np.diff(mv), max_lag)
    pos = lags >= 0
    return int(lags[pos][int(np.argmax(c[pos]))])


def _first_order_lag(x: FloatArray, tau: float, ts: float) -> FloatArray:
    """``x`` through a unit-gain first-order lag of time constant ``tau`` (s), started at rest."""
    if tau <= 0.0:
        return x
    return first_order_lag(x, float(np.exp(-ts / tau)))


def _power_spectra(x: FloatArray, segment: int) -> FloatArray:
    """Welch power spectra (squared RMS per bin) of each row of ``x``: Hann segments of
    ``segment`` samples overlapping by half, each detrended by its least-squares line
    (scipy.signal.welch(..., detrend="linear", scaling="spectrum"), in one batch)."""
    step = segment // 2
    n_seg = 1 + (x.shape[1] - segment) // step
    idx = np.arange(segment)[None, :] + step * np.arange(n_seg)[:, None]
    seg = x[:, idx]  # rows x segments x samples
    t = np.linspace(-1.0, 1.0, segment)
    seg = seg - seg.mean(axis=2, keepdims=True)
    seg = seg - np.einsum("rsk,k->rs", seg, t)[..., None] * t / float(t @ t)
    win = np.hanning(segment + 1)[:-1]  # periodic Hann, as scipy's default
    spec = np.abs(np.fft.rfft(seg * win, axis=2)) ** 2 / float(win.sum()) ** 2
    spec[..., 1:] *= 2.0
    if segment % 2 == 0:
        spec[..., -1] /= 2.0
    return np.asarray(spec.mean(axis=1), dtype=np.float64)


def mv_only_oscillation(
    op: FloatArray, mv: FloatArray, segment: int = 256
) -> tuple[float, float | None, float | None]:
    """K10 of methods §7.2: the strongest oscillation MV has and OP lacks.

    Welch power spectra (Hann, linear detrend, ``segment`` samples) of OP and MV; in the band
    (peak bin ± 2) where MV's power exceeds OP's the most, returns the amplitude of that excess
    (% of travel: sqrt(2·ΣΔP / 1.5), 1.5 = Hann's noise bandwidth in bins), MV's power over OP's
    in the band, and the band's period (samples). Magnitudes only, so the OP–MV delay does not
    matter; a positioner that follows OP (lag, gain error) leaves a ratio near 1.
    """
    n = min(op.size, mv.size)
    if n < 16:
        return 0.0, None, None
    p_op, p_mv = _power_spectra(np.vstack((op[:n], mv[:n])), min(n, segment))
    f = np.fft.rfftfreq(min(n, segment))
    excess = p_mv - p_op
    excess[:2] = 0.0  # drift and the window's mean: air leakage's business, not hunting
    k = int(np.argmax(excess))
    if excess[k] <= 0.0:
        return 0.0, None, None
    band = slice(max(0, k - 2), min(f.size, k + 3))
    amp = float(np.sqrt(2.0 * max(0.0, float(excess[band].sum())) / 1.5))
    ratio = float(p_mv[band].sum() / max(float(p_op[band].sum()), 1e-12))
    return amp, ratio, float(1.0 / f[k])


def _stuck_episodes(
    op: FloatArray,
    mv: FloatArray,
    d_mv: float,
    min_travel: float,
    slip_samples: int,
    op_smooth: FloatArray,
) -> tuple[np.ndarray, np.ndarray, FloatArray, FloatArray, np.ndarray]:
    """Runs where MV stays within ``d_mv`` of the run start while OP travels ``min_travel``
    (net travel of ``op_smooth``, OP averaged against its noise).

    Returns (starts, stops, OP range in the run, MV slip at the breakaway, reversal flags). The
    slip is MV's travel beyond OP's over the breakaway's run of same-direction MV steps larger
    than ``d_mv`` (at most ``slip_samples``): a positioner spreads the jump over a few samples.
    A sequential scan (each run is anchored at its first sample) on plain floats.
    """
    mv_l: list[float] = mv.tolist()
    op_l: list[float] = op.tolist()
    os_l: list[float] = op_smooth.tolist()
    n = len(mv_l)
    starts: list[int] = []
    stops: list[int] = []
    travel: list[float] = []
    jumps: list[float] = []
    reversal: list[bool] = []
    last_dir = 0.0
    k = 0
    while k < n - 1:
        j = k
        anchor = mv_l[k]
        lo = hi = anchor
        while j + 1 < n and abs(mv_l[j + 1] - anchor) <= d_mv:
            j += 1
            v = mv_l[j]
            lo = v if v < lo else lo
            hi = v if v > hi else hi
        if j > k and j + 1 < n:
            # net OP travel (ends averaged over 3 samples): noise adds range, not net travel
            e0, e1 = max(k, j - 2), min(j + 1, k + 3)
            trav = abs(sum(os_l[e0 : j + 1]) / (j + 1 - e0) - sum(os_l[k:e1]) / (e1 - k))
            # OP must travel clearly more than MV: a healthy valve follows OP noise as well
            if trav >= max(min_travel, 3.0 * (hi - lo)):
                direction = 1.0 if mv_l[j + 1] > mv_l[j] else -1.0
                m = j + 1
                while (
                    m + 1 < n
                    and m - j < slip_samples
                    and (mv_l[m + 1] - mv_l[m]) * direction > d_mv
                ):
                    m += 1
                slip = (mv_l[m] - mv_l[j]) * direction - max(0.0, (op_l[m] - op_l[j]) * direction)
                starts.append(k)
                stops.append(j)
                # the valve breaks away the first time OP is S away from where it stuck: the
                # OP range in the episode measures S (net travel only decides the episode)
                seg = op_l[k : j + 1]
                travel.append(max(seg) - min(seg))
                jumps.append(max(0.0, slip))
                reversal.append(last_dir != 0 and direction != last_dir)
        if j + 1 < n:
            step = mv_l[j + 1] - mv_l[j]
            if step != 0.0:
                last_dir = 1.0 if step > 0 else -1.0
        k = j + 1
    return (
        np.asarray(starts, dtype=np.intp),
        np.asarray(stops, dtype=np.intp),
        np.asarray(travel, dtype=np.float64),
        np.asarray(jumps, dtype=np.float64),
        np.asarray(reversal, dtype=bool),
    )


def valve_kpis(
    op: FloatArray, mv: FloatArray, ts: float, params: ValveParams | None = None
) -> tuple[dict[str, float | int | None], float | None, float | None]:
    """All KPIs of §7.2 for one window; returns (kpis, S_v, J_v)."""
    p = params or ValveParams()
    op = np.asarray(op, dtype=np.float64)
    mv = np.asarray(mv, dtype=np.float64)
    delay = op_mv_delay(op, mv, ts, p.max_delay_s)
    op_d = op[: op.size - delay] if delay else op
    mv_d = mv[delay:]
    ev = op_d - mv_d
    n = ev.size
    kpis: dict[str, float | int | None] = {"delay_s": delay * ts}
    kpis["bias"] = float(np.mean(ev))
    kpis["dispersion"] = float(np.std(ev))
    kpis["p99_abs_error"] = float(np.percentile(np.abs(ev), 99))
    # MV = a + b·lag(OP) + c·t: gain error (b), and a drift in time (c, %/h) that OP does not
    # explain. OP passes through the positioner's first-order lag (K4, fitted on a grid of time
    # constants): in a fast oscillating loop the lag would otherwise read as a gain below 1.
    # Smoothed over a few seconds: noise on OP would bias the gain low (errors in variables).
    # The lag is fitted on the raw pair as well as the delay-aligned one: the cross-correlation
    # delay takes up a lag's phase but not its attenuation.
    w = max(5, round(p.smooth_s / ts))
    best: tuple[float, float, np.ndarray, np.ndarray, np.ndarray] | None = None
    pairs = [(op_d, mv_d)] + ([(op, mv)] if delay else [])
    for op_x, mv_x in pairs:
        op_s = moving_average(op_x, w)
        mv_s = moving_average(mv_x, w)
        use_gain = float(np.ptp(op_s)) >= p.gain_min_span
        t_x = np.arange(op_s.size) * ts / 3600.0
        for tau in (0.0, *p.lag_grid_s):
            if 0.0 < tau < 0.1 * ts:
                continue
            op_l = _first_order_lag(op_s, tau, ts)
            reg_l = np.column_stack([np.ones(op_s.size), t_x] + ([op_l] if use_gain else []))
            target_l = mv_s if use_gain else mv_s - op_l
            coef_l, *_ = np.linalg.lstsq(reg_l, target_l, rcond=None)
            sse = float(np.mean((target_l - reg_l @ coef_l) ** 2))
            if best is None or sse < best[0]:
                best = (sse, tau, reg_l, target_l, coef_l)
    assert best is not None
    _, tau_best, reg, target, coef = best
    kpis["lag_s"] = tau_best
    use_gain = reg.shape[1] == 3
    kpis["gain"] = float(coef[2]) if use_gain else None
    kpis["drift_per_hour"] = -float(coef[1]) if reg[-1, 1] > 0 else 0.0  # + = MV falls behind
    resid_full = target - reg @ coef
    reg0 = reg[:, [0, *range(2, reg.shape[1])]]
    coef0, *_ = np.linalg.lstsq(reg0, target, rcond=None)
    resid0 = target - reg0 @ coef0
    var0 = float(np.var(resid0))
    kpis["drift_share"] = float(1.0 - np.var(resid_full) / var0) if var0 > 0 else 0.0
    kpis["residual_std"] = float(np.std(resid_full))
    # stuck episodes -> stuck fraction, S_v, J_v
    d_mv = max(p.resolution, 3.0 * noise_sigma(mv_d))
    sig_op = noise_sigma(op_d)
    w_op = int(np.clip(round((sig_op / p.op_smooth_noise) ** 2), 1, 15))
    op_e = moving_average(op_d, w_op) if w_op > 1 else op_d
    min_trav = max(p.stuck_min_travel, 3.0 * sig_op / np.sqrt(w_op))
    slip_n = max(1, round(p.slip_s / ts))
    st, sp_, trav, jump, rev = _stuck_episodes(op_d, mv_d, d_mv, min_trav, slip_n, op_e)
    moving_op = np.abs(np.diff(op_d)) > 0.5 * p.resolution
    stuck_mask = np.zeros(n - 1, dtype=bool)
    for a_, b_ in zip(st.tolist(), sp_.tolist(), strict=True):
        stuck_mask[a_:b_] = True
    f_st = float(np.sum(stuck_mask & moving_op)) / max(1, int(np.sum(moving_op)))
    kpis["stuck_fraction"] = f_st
    kpis["stuck_episodes"] = int(st.size)
    s_v = float(np.median(trav[rev])) if rev.any() else None
    j_v = float(np.median(jump[rev])) if rev.any() else None
    kpis["S_v"] = s_v
    kpis["J_v"] = j_v
    # hunting (K10): power MV has in a band where OP has little (delay-free amplitude spectra)
    mv_only, ratio, period = mv_only_oscillation(op_d, mv_d, p.spectrum_segment)
    kpis["mv_only_oscillation"] = mv_only
    kpis["mv_only_ratio"] = ratio
    kpis["mv_only_period_s"] = period * ts if period is not None else None
    # rate limit: MV speed (over ~2 s, above the sensor noise) pinned at its maximum while
    # the error is large and MV moves toward OP
    wr = max(2, round(p.speed_window_s / ts))
    speed = (mv_d[wr:] - mv_d[:-wr]) / (wr * ts)
    vmax = float(np.percentile(np.abs(speed), 99)) if speed.size else 0.0
    toward = np.sign(speed) == np.sign(ev[wr:])
    at_limit = (np.abs(speed) >= 0.8 * vmax) & (np.abs(ev[wr:]) > p.rate_error) & toward
    kpis["max_speed_per_s"] = vmax
    kpis["rate_limited_share"] = float(np.mean(at_limit)) if vmax > 0 else 0.0
    # A rate limit pins the speed whatever the error; a positioner lag moves at speed ∝ error.
    big = (np.abs(ev[wr:]) > p.rate_error) & toward
    if int(big.sum()) >= 10:
        sp_big = np.abs(speed[big])
        ratio = sp_big / np.abs(ev[wr:][big])
        cv_speed = float(np.std(sp_big) / np.mean(sp_big)) if np.mean(sp_big) > 0 else 1.0
        cv_ratio = float(np.std(ratio) / np.mean(ratio)) if np.mean(ratio) > 0 else 0.0
        kpis["speed_saturation"] = cv_ratio / max(cv_speed, 1e-6)
    else:
        kpis["speed_saturation"] = 0.0
    return kpis, s_v, j_v


@dataclass(frozen=True)
class _Reading:
    """The indicators of one window and what the class tests share: friction (the stem stuck
    most of the time with a stickband) and hunting (MV cycling on its own)."""

    kpis: dict[str, float | int | None]
    s_v: float | None
    j_v: float | None
    friction: bool
    hunts: bool

    def value(self, name: str) -> float:
        """An indicator as a number (0 when not computed)."""
        return float(self.kpis[name] or 0.0)


def _undersized(r: _Reading, p: ValveParams) -> ValveAssessment | None:
    """The stem at its speed limit while a large error asks for more."""
    if not (
        r.value("rate_limited_share") > p.rate_share
        and r.value("speed_saturation") > p.speed_saturation
    ):
        return None
    why = (
        f"MV at its speed limit {r.kpis['max_speed_per_s']:.2f} %/s with a large error "
        f"{100 * r.value('rate_limited_share'):.1f} % of the time"
    )
    return ValveAssessment("actuator_undersized", r.kpis, None, None, [why])


def _air_leakage(r: _Reading, p: ValveParams) -> ValveAssessment | None:
    """The stem drifts toward its fail position. Friction and hunting move MV on their own:
    the static fits (drift, calibration) read their cycles as a trend or a map error, so they
    must not be behind this verdict or the next."""
    drift, share = r.value("drift_per_hour"), r.value("drift_share")
    if not (abs(drift) > p.drift_limit and share > p.drift_share and not (r.friction or r.hunts)):
        return None
    why = f"e_v drifts {drift:+.2f} %/h ({100 * share:.0f} % of its variance)"
    return ValveAssessment("air_leakage", r.kpis, None, None, [why])


def _positioner_fault(r: _Reading, p: ValveParams) -> ValveAssessment | None:
    """A steady offset or gain between OP and MV: the positioner's calibration."""
    bias, gain = r.value("bias"), r.kpis["gain"]
    gain_bad = gain is not None and abs(float(gain) - 1.0) > p.gain_limit
    steady = r.value("residual_std") < p.calibration_scatter
    if not ((abs(bias) > p.bias_limit or gain_bad) and steady and not (r.friction or r.hunts)):
        return None
    why = f"positioner calibration: bias {bias:+.2f} %" + (
        f", gain {float(gain):.3f}" if gain is not None else ""
    )
    return ValveAssessment("positioner_fault", r.kpis, None, None, [why])


def _friction(r: _Reading, p: ValveParams) -> ValveAssessment | None:
    """Stick-slip (a slip jump) or a deadband without slip, sized from MV(OP)."""
    if not r.friction or r.s_v is None:
        return None
    s_v, j_v = r.s_v, r.j_v
    if j_v is not None and j_v > p.slip_ratio * s_v:
        f_st = r.value("stuck_fraction")
        why = f"stick-slip: S_v = {s_v:.2f} %, J_v = {j_v:.2f} %, f_st = {f_st:.2f}"
        return ValveAssessment("stiction", r.kpis, s_v, j_v, [why])
    why = f"deadband without slip: S_v = {s_v:.2f} %, J_v = {j_v or 0:.2f} %"
    return ValveAssessment("deadband_backlash", r.kpis, s_v, j_v, [why])


def _positioner_tuning(r: _Reading, p: ValveParams) -> ValveAssessment | None:
    """The stem hunts: MV oscillates in a band where OP does not."""
    ratio = r.kpis["mv_only_ratio"]
    if not r.hunts or ratio is None:
        return None
    why = (
        f"MV oscillates on its own: amplitude {r.value('mv_only_oscillation'):.2f} %, period "
        f"{r.kpis['mv_only_period_s']:.1f} s, {float(ratio):.0f}x OP's power in that band"
    )
    return ValveAssessment("positioner_tuning", r.kpis, None, None, [why])


VALVE_CLASSES: tuple[Callable[[_Reading, ValveParams], ValveAssessment | None], ...] = (
    _undersized,
    _air_leakage,
    _positioner_fault,
    _friction,
    _positioner_tuning,
)
"""The actuator classes of methods §7.3, in the order they are tested: the first wins."""


def classify_valve(
    op: FloatArray, mv: FloatArray, ts: float, params: ValveParams | None = None
) -> ValveAssessment:
    """Actuator state of methods §7.3, evaluated in order (``VALVE_CLASSES``); the first
    matching class wins, ``ok`` when none does."""
    p = params or ValveParams()
    if float(np.ptp(mv)) < p.resolution and float(np.ptp(op)) >= p.stuck_min_travel:
        kp: dict[str, float | int | None] = {"mv_range": float(np.ptp(mv))}
        return ValveAssessment("data_quality", kp, None, None, ["MV flat while OP moves"])
    kpis, s_v, j_v = valve_kpis(op, mv, ts, p)
    f_st = float(kpis["stuck_fraction"] or 0.0)
    ratio = kpis["mv_only_ratio"]
    hunting = float(kpis["mv_only_oscillation"] or 0.0)
    reading = _Reading(
        kpis,
        s_v,
        j_v,
        friction=f_st > p.stuck_fraction and s_v is not None and s_v > p.min_stickband,
        hunts=hunting > p.hunting_amplitude
        and ratio is not None
        and float(ratio) > p.hunting_ratio,
    )
    for test in VALVE_CLASSES:
        if (found := test(reading, p)) is not None:
            return found
    return ValveAssessment("ok", kpis, None, None, [])
