"""Actuator KPIs from the valve position error e_v = OP − MV (methods.md §7.2) and the actuator
classification (§7.3). A reconstruction of the PCU advanced chain (Bacci di Capaci, Scali et al.
2013; thesis ch. 6): every limit is a parameter, calibrated on the generated actuator cases.

OP and MV in % of travel, times in seconds. The OP–MV delay is removed first (cross-correlation
of the increments), then:

- bias μ_v, dispersion σ_v, 99th percentile of |e_v|;
- linear fit MV = a + b·OP (gain and offset errors of the positioner calibration);
- stuck episodes: MV still while OP travels; their OP travel before a breakaway after a reversal
  estimates the stickband S_v, the MV jump at breakaway the slip J_v (Kano et al. 2004);
- MV-only oscillation (hunting): a regular oscillation of e_v that OP does not have;
- drift of e_v over the window (%/h): air leakage pulls the stem toward the fail position;
- rate limit: MV speed saturating at its maximum while e_v is large (undersized actuator).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from plantcheck.diagnosis.oscillation import detect_oscillation
from plantcheck.diagnosis.signal_tools import FloatArray, fft_ccf, moving_average, noise_sigma

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
    hunting_amplitude: float = 0.3
    """MV-only oscillation amplitude (% of travel) above which the positioner hunts."""
    hunting_ratio: float = 0.5
    """... and at least this share of OP's own oscillation amplitude (MV is the source)."""
    rate_share: float = 0.02
    """Share of samples at the MV speed limit (with a large e_v) -> undersized actuator."""
    rate_error: float = 1.0
    """|e_v| (% of travel) that counts as large while MV moves at its limit."""
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


def _stuck_episodes(
    op: FloatArray, mv: FloatArray, d_mv: float, min_travel: float
) -> tuple[np.ndarray, np.ndarray, FloatArray, FloatArray, np.ndarray]:
    """Runs where MV stays within ``d_mv`` of the run start while OP travels ``min_travel``.

    Returns (starts, stops, OP travel in the run, MV jump at the breakaway, reversal flags).
    """
    n = mv.size
    starts: list[int] = []
    stops: list[int] = []
    travel: list[float] = []
    jumps: list[float] = []
    reversal: list[bool] = []
    last_dir = 0.0
    k = 0
    while k < n - 1:
        j = k
        anchor = mv[k]
        while j + 1 < n and abs(mv[j + 1] - anchor) <= d_mv:
            j += 1
        if j > k:
            # net OP travel (ends averaged over 3 samples): noise adds range, not net travel
            trav = abs(
                float(np.mean(op[max(k, j - 2) : j + 1]) - np.mean(op[k : min(j + 1, k + 3)]))
            )
            mv_trav = float(mv[k : j + 1].max() - mv[k : j + 1].min())
            # OP must travel clearly more than MV: a healthy valve follows OP noise as well
            if trav >= max(min_travel, 3.0 * mv_trav) and j + 1 < n:
                after = mv[min(n - 1, j + 3)] - mv[j]
                direction = float(np.sign(after))
                starts.append(k)
                stops.append(j)
                # the valve breaks away the first time OP is S away from where it stuck: the
                # OP range in the episode measures S (net travel only decides the episode)
                travel.append(float(np.ptp(op[k : j + 1])))
                jumps.append(abs(float(mv[j + 1] - mv[j])))
                reversal.append(last_dir != 0 and direction != last_dir)
        if j + 1 < n:
            step = mv[j + 1] - mv[j]
            if abs(step) > 0:
                last_dir = float(np.sign(step))
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
    t_h = np.arange(n) * ts / 3600.0
    kpis: dict[str, float | int | None] = {"delay_s": delay * ts}
    kpis["bias"] = float(np.mean(ev))
    kpis["dispersion"] = float(np.std(ev))
    kpis["p99_abs_error"] = float(np.percentile(np.abs(ev), 99))
    # MV = a + b·OP + c·t: gain error (b), and a drift in time (c, %/h) that OP does not explain
    # smoothed over a few seconds: noise on OP would bias the gain low (errors in variables)
    w = max(5, round(p.smooth_s / ts))
    op_s = moving_average(op_d, w)
    mv_s = moving_average(mv_d, w)
    span = float(np.ptp(op_s))
    use_gain = span >= p.gain_min_span
    cols = [np.ones(n), t_h] + ([op_s] if use_gain else [])
    reg = np.column_stack(cols)
    target = mv_s if use_gain else mv_s - op_s
    coef, *_ = np.linalg.lstsq(reg, target, rcond=None)
    kpis["gain"] = float(coef[2]) if use_gain else None
    kpis["drift_per_hour"] = -float(coef[1]) if t_h[-1] > 0 else 0.0  # + = MV falls behind
    resid_full = target - reg @ coef
    reg0 = reg[:, [0, *range(2, reg.shape[1])]]
    coef0, *_ = np.linalg.lstsq(reg0, target, rcond=None)
    resid0 = target - reg0 @ coef0
    var0 = float(np.var(resid0))
    kpis["drift_share"] = float(1.0 - np.var(resid_full) / var0) if var0 > 0 else 0.0
    kpis["residual_std"] = float(np.std(resid_full))
    # stuck episodes -> stuck fraction, S_v, J_v
    d_mv = max(p.resolution, 3.0 * noise_sigma(mv_d))
    min_trav = max(p.stuck_min_travel, 3.0 * noise_sigma(op_d))
    st, sp_, trav, jump, rev = _stuck_episodes(op_d, mv_d, d_mv, min_trav)
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
    # hunting: a regular oscillation of e_v beyond what a positioner lag explains
    # (a first-order lag gives e_v ≈ τ·dOP/dt)
    dop = np.gradient(op_s)
    den_l = float(dop @ dop)
    lag_fit = float((ev - ev.mean()) @ dop) / den_l if den_l > 0 else 0.0
    e_res = ev - ev.mean() - lag_fit * dop
    ev_osc = detect_oscillation(e_res, ts)
    mv_only = float(ev_osc.amplitude or 0.0) if ev_osc.oscillating else 0.0
    kpis["mv_only_oscillation"] = mv_only
    # a hunting positioner is the source of the cycle: its residual is large next to OP's own
    # oscillation; a healthy positioner in an oscillating loop leaves a small lag residual
    op_osc = detect_oscillation(op_s, ts)
    op_amp = float(op_osc.amplitude or 0.0) if op_osc.oscillating else 0.0
    kpis["mv_only_ratio"] = mv_only / op_amp if op_amp > 0 else None
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


def classify_valve(
    op: FloatArray, mv: FloatArray, ts: float, params: ValveParams | None = None
) -> ValveAssessment:
    """Actuator state of methods §7.3, evaluated in order; the first matching class wins."""
    p = params or ValveParams()
    if float(np.ptp(mv)) < p.resolution and float(np.ptp(op)) >= p.stuck_min_travel:
        kp: dict[str, float | int | None] = {"mv_range": float(np.ptp(mv))}
        return ValveAssessment("data_quality", kp, None, None, ["MV flat while OP moves"])
    kpis, s_v, j_v = valve_kpis(op, mv, ts, p)
    reasons: list[str] = []
    bias = float(kpis["bias"] or 0.0)
    drift = float(kpis["drift_per_hour"] or 0.0)
    drift_share = float(kpis["drift_share"] or 0.0)
    f_st = float(kpis["stuck_fraction"] or 0.0)
    gain = kpis["gain"]
    hunting = float(kpis["mv_only_oscillation"] or 0.0)
    rate_share = float(kpis["rate_limited_share"] or 0.0)
    friction = f_st > p.stuck_fraction and s_v is not None and s_v > p.min_stickband
    saturated = float(kpis["speed_saturation"] or 0.0) > p.speed_saturation
    if rate_share > p.rate_share and saturated:
        reasons.append(
            f"MV at its speed limit {kpis['max_speed_per_s']:.2f} %/s with a large error "
            f"{100 * rate_share:.1f} % of the time"
        )
        return ValveAssessment("actuator_undersized", kpis, None, None, reasons)
    if abs(drift) > p.drift_limit and drift_share > p.drift_share:
        reasons.append(f"e_v drifts {drift:+.2f} %/h ({100 * drift_share:.0f} % of its variance)")
        return ValveAssessment("air_leakage", kpis, None, None, reasons)
    gain_bad = gain is not None and abs(float(gain) - 1.0) > p.gain_limit
    steady = float(kpis["residual_std"] or 0.0) < p.calibration_scatter
    if (abs(bias) > p.bias_limit or gain_bad) and steady and not friction:
        reasons.append(
            f"positioner calibration: bias {bias:+.2f} %"
            + (f", gain {float(gain):.3f}" if gain is not None else "")
        )
        return ValveAssessment("positioner_fault", kpis, None, None, reasons)
    if friction and s_v is not None:
        if j_v is not None and j_v > p.slip_ratio * s_v:
            reasons.append(f"stick-slip: S_v = {s_v:.2f} %, J_v = {j_v:.2f} %, f_st = {f_st:.2f}")
            return ValveAssessment("stiction", kpis, s_v, j_v, reasons)
        reasons.append(f"deadband without slip: S_v = {s_v:.2f} %, J_v = {j_v or 0:.2f} %")
        return ValveAssessment("deadband_backlash", kpis, s_v, j_v, reasons)
    ratio = kpis["mv_only_ratio"]
    if hunting > p.hunting_amplitude and (ratio is None or float(ratio) > p.hunting_ratio):
        reasons.append(f"MV oscillates on its own (amplitude {hunting:.2f} %)")
        return ValveAssessment("positioner_tuning", kpis, None, None, reasons)
    return ValveAssessment("ok", kpis, None, None, reasons)
