"""The evidence a window gives: the chain's test outputs as one vector, the input of the
learned decision (issue 46).

Every entry is dimensionless (ratios to the noise, to the sample time, to the window) so that
the decision learned on simulated loops reads any plant's units. An entry the chain did not
compute on a window (the stiction tests of a loop that does not oscillate, say) is NaN; the
model learns what its absence means.
"""

from __future__ import annotations

import math

import numpy as np

from plantcheck.diagnosis.signal_tools import (
    FloatArray,
    SignalSpectrum,
    detrend,
    hann_power,
    mean,
    noise_sigma,
    std,
)

EVIDENCE_VERSION = 10
"""Raised whenever what the chain gathers changes: cached corpus evidence is then redrawn.
Version 10: the window is read through ``chain._prepare`` as a diagnosis reads it (the held
OP as manual time, the cut after a retuning, the longest automatic stretch).
Version 9: the two-model test of the stick-slip events reads residuals below a billionth of
the PV's level a sample as rounding (``stick_slip.ROUNDING_LEVEL``): noise-free records'
events no longer rest on the order of a sum.
Version 8: the corpus gathers what a diagnosis weighs (the stiction tests wherever a period
was found, the oscillation test on windows the window checks decided); until then it skipped
them, and 4 windows in 10 were weighed on inputs the fit had not seen present for them."""

FEATURES: dict[str, str] = {
    "log_samples": "log10 of the window's samples",
    "integrating": "1 for a level (integrating) loop, else 0",
    "clamp_share": "share of the window with OP resting at a limit (any level) and PV off SP",
    "clamp_error": "mean |error| while clamped, in noise σ of the error",
    "op_at_extreme": "share of samples with OP exactly at its window maximum or minimum",
    "error_sd_noise": "σ of the control error over its noise σ (variability)",
    "error_offset": "|mean error| over its σ: PV held off set point on one side",
    "op_sd": "σ of OP, % of travel",
    "op_noise_share": "OP's sample-to-sample noise σ over its σ",
    "pv_unique_fraction": "share of distinct PV values (quantised or compressed PV reads low)",
    "pv_unchanged_fraction": "share of samples where PV does not change",
    "sp_steps": "set-point steps found",
    "oscillating": "1 when the oscillation test found a sustained oscillation, else 0",
    "on_op": "1 when the oscillation showed in OP rather than the error",
    "regularity": "Thornhill's regularity of the oscillation",
    "log_period_samples": "log10 of the oscillation period in samples",
    "log_cycles": "log10 of the cycles the analysed stretch holds",
    "amplitude_noise": "oscillation amplitude over the error's noise σ",
    "load_count": "Hägglund's load count",
    "period_over_ti": "oscillation period over the identified integral time",
    "decay_ratio": "ACF decay ratio of the cycle (Miao & Seborg 1999)",
    "controller_fit": "R² of the identified PI controller",
    "idle_index": "Hägglund's idle index",
    "sp_step_slowness": "set-point responses' closed-loop time constant over their dead time",
    "sp_step_overshoot": "set-point responses' median overshoot",
    "load_recovery_slowness": "load recoveries' return time over departure time",
    "relay": "relay-shape index of the error's half-cycles",
    "curve_fit": "curve-fit index (He et al. 2007)",
    "area_ratio": "area-ratio index (Singhal & Salsbury 2005)",
    "bicoherence": "non-Gaussianity index of the error (Choudhury et al. 2004)",
    "cross_correlation": "OP-PV cross-correlation's phase index (Horch 1999)",
    "histogram": "PV histogram index (Horch 2000)",
    "vote_score": "the stiction tests' vote score",
    "stick_slip": "stick-slip events' test value",
    "events": "stick-slip events found",
    "strong_events": "events the valve-step model confirms",
    "event_reversals": "successive events in opposite directions",
    "event_travel": "median OP travel at breakaway, % of OP's range",
    "unresponsive": "1 when the valve did not answer a large OP travel",
    "error_kurtosis": "kurtosis of the detrended error (noise 3, a sine 1.5, a square wave 1)",
    "error_skew": "|skewness| of the detrended error",
    "op_kurtosis": "kurtosis of the detrended OP",
    "pv_jump": "largest |ΔPV| over the σ of ΔPV (a slip stands out of the increments)",
    "dop_dpv_corr": "correlation of OP's and PV's increments",
    "kc_share": "identified Kc × σ(error) over σ(OP): the proportional share of OP's moves",
    "acf_time_over_ti": "lag where the error's ACF falls below 1/e, over the integral time",
    "error_band_0": "share of the error's power below 0.003 / Ti (the whole window)",
    "error_band_1": "share of the error's power at 0.003-0.01 / Ti",
    "error_band_2": "share of the error's power at 0.01-0.03 / Ti",
    "error_band_3": "share of the error's power at 0.03-0.1 / Ti",
    "error_band_4": "share of the error's power at 0.1-0.3 / Ti",
    "error_band_5": "share of the error's power at 0.3-1 / Ti",
    "error_band_6": "share of the error's power at 1-3 / Ti",
    "error_band_7": "share of the error's power at 3-10 / Ti",
    "peak_f_ti": "log10 of the error spectrum's peak frequency times Ti",
    "peak_share": "share of the error's power within a bin of its spectral peak",
    "harmonic_2": "power at twice the peak frequency over the peak's",
    "harmonic_3": "power at three times the peak frequency over the peak's (odd harmonics: "
    "a square or triangular cycle)",
    "spectral_flatness": "geometric over arithmetic mean of the error's power spectrum (white "
    "noise 0.56 with a Hann window, a pure cycle near 0)",
    "error_lag1": "the error's autocorrelation at one sample (white noise 0, slow moves near 1)",
    "log_error_acf_samples": "log10 of the error's correlation time in samples (its ACF, over "
    "lag 1's, below 1/e)",
    "log_op_acf_samples": "log10 of OP's correlation time in samples",
    "op_error_acf_ratio": "log10 of OP's correlation time over the error's: a loop that rejects "
    "its loads moves OP slowly while the error stays short",
    "error_acf_min": "the deepest the error's ACF falls within four times its first zero lag "
    "(a well-damped loop's undershoot; none where the error only decays)",
    "error_acf_shape": "the lag the error's ACF falls below 0.5 over the lag it falls below 0.1 "
    "(an exponential decay 0.30, a cut-off sooner)",
    "error_acf_2": "the error's ACF at twice its correlation time",
    "error_acf_3": "the error's ACF at three times its correlation time",
    "error_acf_5": "the error's ACF at five times its correlation time",
    "op_acf_min": "the deepest OP's ACF falls within four times its first zero lag",
    "op_acf_2": "OP's ACF at twice its correlation time",
    "op_acf_3": "OP's ACF at three times its correlation time",
    "op_acf_5": "OP's ACF at five times its correlation time",
    "op_error_ccf_0": "OP's and the error's correlation at lag 0, signed against its peak "
    "(the controller's direction taken out)",
    "op_error_ccf_peak": "the largest |correlation| of the error with OP earlier (lags 0 to ten "
    "correlation times)",
    "op_error_ccf_lag": "log10 of (that lag + 1) over the error's correlation time",
    "error_op_ccf_peak": "the largest |correlation| of OP with the error earlier (OP answering "
    "the error)",
    "error_op_ccf_lag": "log10 of (that lag + 1) over the error's correlation time",
    "kc_over_simc": "log10 of the identified Kc over the SIMC Kc of a quick process model",
    "ti_over_simc": "log10 of the identified Ti over the SIMC Ti of that model",
    "dead_time_share": "that model's θ/(τ + θ) (none for an integrating loop)",
    "loop_gain": "log10 of |Kc·K| (times θ for an integrating loop)",
    "process_fit": "that model's simulated-output fit (1 perfect, 0 the mean's)",
    "log_dead_time_samples": "log10 of that model's dead time in samples",
}
"""Each evidence entry's name and meaning, in the order of the model's input vector."""

FEATURE_NAMES: tuple[str, ...] = tuple(FEATURES)


def window_evidence(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray,
    indices: dict[str, float],
    integrating: bool,
    error_noise: float | None = None,
    op_noise: float | None = None,
) -> dict[str, float]:
    """The entries every usable window has, from its cleaned signals and window checks (with
    the noise σ of SP − PV and of OP where the checks read them: ``noise_sigma`` else)."""
    e = sp - pv
    n = int(pv.size)
    sd_e = std(e)
    sigma = noise_sigma(e) if error_noise is None else error_noise
    op_sigma = noise_sigma(op) if op_noise is None else op_noise
    sd_op = std(op)
    op_hi, op_lo = float(np.max(op)), float(np.min(op))
    at = (op >= op_hi - 1e-9 * max(1.0, abs(op_hi))) | (op <= op_lo + 1e-9 * max(1.0, abs(op_lo)))
    return {
        "log_samples": math.log10(max(n, 1)),
        "integrating": float(integrating),
        "clamp_share": float(indices.get("saturation_fraction", 0.0)),
        "clamp_error": float(indices.get("clamp_error_noise", math.nan)),
        "op_at_extreme": float(np.mean(at)) if sd_op > 0 else 1.0,
        "error_sd_noise": sd_e / sigma if sigma > 0 else math.nan,
        "error_offset": abs(mean(e)) / sd_e if sd_e > 0 else math.nan,
        "op_sd": sd_op,
        "op_noise_share": op_sigma / sd_op if sd_op > 0 else math.nan,
        "pv_unique_fraction": float(indices.get("pv_unique_fraction", math.nan)),
        "pv_unchanged_fraction": float(indices.get("pv_unchanged_fraction", math.nan)),
        "sp_steps": float(indices.get("sp_steps", 0.0)),
    }


def _kurtosis(x: FloatArray) -> float:
    # products, not d**4: numpy's power by an integer other than 2 calls pow() per element,
    # fifteen times slower (0.17 ms on 3,600 samples)
    d = x - mean(x)
    d2 = d * d
    v = mean(d2)
    return mean(d2 * d2) / (v * v) if v > 0 else math.nan


def _skew(x: FloatArray) -> float:
    d = x - mean(x)
    d2 = d * d
    v = mean(d2)
    return abs(mean(d2 * d)) / v**1.5 if v > 0 else math.nan


def _first_below(r: FloatArray, level: float) -> int:
    """First lag (samples, ``r[0]`` being lag 1) where ``r`` falls below ``level``; one past
    its end if never."""
    below = np.flatnonzero(r < level)
    return int(below[0]) + 1 if below.size else int(r.size) + 1


def _acf_time(x: SignalSpectrum) -> float | None:
    """First lag (samples) where the ACF of ``x`` falls below 1/e; None if never."""
    n = x.centred.size
    if n < 8 or not np.any(x.centred):
        return None
    acf = x.acf(n)
    lag = _first_below(acf[1:], 1.0 / math.e)
    return float(lag) if lag < acf.size else None


def shape_evidence(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray,
    kc: float | None,
    ti_samples: float | None,
    error: SignalSpectrum | None = None,
) -> dict[str, float | None]:
    """Distribution and increment statistics of the analysed stretch: the error's and OP's
    kurtosis (Choudhury et al. 2004 read non-Gaussianity as non-linearity), PV's largest jump
    against its increments, how OP's and PV's increments go together, the proportional
    share of OP's moves and the error's correlation time against the integral time
    (``error``: the detrended SP − PV's spectrum, where the caller has it)."""
    ed, opd = detrend(sp - pv), detrend(op)
    dpv, dop = np.diff(pv), np.diff(op)
    sd_dpv, sd_dop = std(dpv), std(dop)
    sd_e, sd_op = std(ed), std(opd)
    corr = (
        mean((dpv - mean(dpv)) * (dop - mean(dop))) / (sd_dpv * sd_dop)
        if sd_dpv > 0 and sd_dop > 0
        else None
    )
    tau = _acf_time(SignalSpectrum.of(ed) if error is None else error)
    return {
        "error_kurtosis": _kurtosis(ed),
        "error_skew": _skew(ed),
        "op_kurtosis": _kurtosis(opd),
        "pv_jump": float(np.max(np.abs(dpv - mean(dpv)))) / sd_dpv if sd_dpv > 0 else None,
        "dop_dpv_corr": corr,
        "kc_share": abs(kc) * sd_e / sd_op if kc is not None and sd_op > 0 else None,
        "acf_time_over_ti": tau / ti_samples if tau is not None and ti_samples else None,
    }


BAND_EDGES = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0)
"""Edges of the error's power bands, in cycles per integral time: the bands sit where the
loop's own dynamics put them (a sluggish loop's power low, an aggressive one's near its
crossover, a periodic load anywhere), whatever the sample time."""


def spectral_evidence(e: FloatArray, ti_samples: float | None) -> dict[str, float | None]:
    """Where the control error's power lies against the controller's integral time, and the
    shape of its spectral peak (Hann-windowed periodogram, Welch 1967; harmonics of a
    limit cycle, Thornhill & Hägglund 1997)."""
    n = int(e.size)
    if n < 16:
        return {}
    nfft = 1 << math.ceil(math.log2(n))
    power = hann_power(e, nfft)
    power[0] = 0.0
    total = float(power.sum())
    if total <= 0:
        return {}
    k0 = int(np.argmax(power[1:])) + 1

    def near(k: int) -> float:
        return float(power[max(1, k - 1) : min(power.size, k + 2)].sum())

    peak = near(k0)
    out: dict[str, float | None] = {
        "peak_share": peak / total,
        "harmonic_2": near(2 * k0) / peak if 2 * k0 < power.size else None,
        "harmonic_3": near(3 * k0) / peak if 3 * k0 < power.size else None,
        "spectral_flatness": float(np.exp(np.mean(np.log(power[1:] + 1e-300))))
        / float(np.mean(power[1:])),
    }
    if ti_samples:
        f_ti = np.fft.rfftfreq(nfft) * ti_samples
        cum = np.concatenate([[0.0], np.cumsum(power)])
        idx = np.searchsorted(f_ti, np.asarray(BAND_EDGES))
        out["error_band_0"] = float(cum[idx[0]]) / total
        for b in range(1, len(BAND_EDGES)):
            out[f"error_band_{b}"] = float(cum[idx[b]] - cum[idx[b - 1]]) / total
        out["peak_f_ti"] = math.log10(max(float(f_ti[k0]), 1e-6))
    return out


def _acf_shape(r: FloatArray, name: str) -> tuple[float, dict[str, float | None]]:
    """The correlation time (samples) of ACF ``r`` (lags from 1, over lag 1's value) and the
    entries of its shape: its deepest undershoot and its values at 2, 3 and 5 times that."""
    t = _first_below(r, 1.0 / math.e)
    zero = _first_below(r, 0.0)
    out: dict[str, float | None] = {f"{name}_min": float(np.min(r[: min(r.size, 4 * zero)]))}
    for m in (2, 3, 5):
        out[f"{name}_{m}"] = float(r[m * t - 1]) if m * t <= r.size else None
    return float(t), out


def correlation_evidence(
    e: FloatArray, op: FloatArray, error: SignalSpectrum | None = None
) -> dict[str, float | None]:
    """How the control error and OP correlate in time, over the whole window and free of its
    time scale: each one's correlation time and the shape of its autocorrelation (the decay
    of a sluggish loop, the undershoot of a well-damped one, the cut-off of a dead-time
    dominant one: Harris 1989 reads the error's ACF against the dead time), how much longer
    OP stays correlated than the error (the share of a load the loop rejects), and where the
    error and OP correlate most (Box & Jenkins 1970's cross-correlation, unwhitened).

    Autocorrelations are over lag 1's value, so measurement noise (white, all at lag 0)
    changes the shape little. Both signals are detrended first (``error``: the detrended
    error's spectrum, where the caller has it)."""
    n = int(e.size)
    if n < 32:
        return {}
    err = SignalSpectrum.of(detrend(e)) if error is None else error
    out_op = SignalSpectrum.of(detrend(op))
    ed, od, nfft = err.centred, out_op.centred, err.nfft
    fe, fo = err.spectrum, out_op.spectrum
    see, soo = float(ed @ ed), float(od @ od)
    if see <= 0 or soo <= 0:
        return {}
    acf_e = err.autocovariance[: n // 2] / see
    acf_o = out_op.autocovariance[: n // 2] / soo
    out: dict[str, float | None] = {"error_lag1": float(acf_e[1])}
    if acf_e[1] <= 0 or acf_o[1] <= 0:
        return out
    re, ro = acf_e[1:] / acf_e[1], acf_o[1:] / acf_o[1]
    te, shape_e = _acf_shape(re, "error_acf")
    to, shape_o = _acf_shape(ro, "op_acf")
    out.update(shape_e)
    out.update(shape_o)
    out["log_error_acf_samples"] = math.log10(te)
    out["log_op_acf_samples"] = math.log10(to)
    out["op_error_acf_ratio"] = math.log10(to / te)
    out["error_acf_shape"] = _first_below(re, 0.5) / _first_below(re, 0.1)
    # cc[k] = Σ op(t)·e(t+k): the error after OP at k >= 0, before it at k < 0 (the tail)
    cc = np.fft.irfft(np.conj(fo) * fe, nfft) / math.sqrt(see * soo)
    span = int(min(n // 4, 10 * te))
    after, before = cc[: span + 1], cc[::-1][:span]
    k = int(np.argmax(np.abs(after)))
    out["op_error_ccf_0"] = float(after[0]) * (1.0 if after[k] >= 0 else -1.0)
    out["op_error_ccf_peak"] = float(abs(after[k]))
    out["op_error_ccf_lag"] = math.log10((k + 1) / te)
    if before.size:
        j = int(np.argmax(np.abs(before)))
        out["error_op_ccf_peak"] = float(abs(before[j]))
        out["error_op_ccf_lag"] = math.log10((j + 2) / te)
    return out


def evidence_vector(evidence: dict[str, float | None]) -> FloatArray:
    """The entries in ``FEATURE_NAMES`` order, NaN where not computed."""
    return np.array(
        [math.nan if evidence.get(k) is None else float(evidence[k]) for k in FEATURE_NAMES],  # type: ignore[arg-type]
        dtype=np.float64,
    )


def process_evidence(
    K: float,
    tau: float,
    theta: float,
    fit: float,
    kc: float | None,
    ti_samples: float | None,
    integrating: bool,
) -> dict[str, float | None]:
    """The identified controller against the SIMC setting of a quick process model
    (Skogestad 2003, τc = θ): Kc_SIMC = τ/(K·2θ), Ti_SIMC = min(τ, 8θ); for an integrating
    process Kc_SIMC = 1/(K·2θ), Ti_SIMC = 8θ. K in PV units per % (per sample for an
    integrating process), τ and θ in samples, θ taken half a sample longer for the hold.

    A sluggish and an aggressive loop differ from a well-tuned one in where their controller
    sits against the process, which no statistic of the error alone reads: a dead time of 2
    samples and one of 40 leave the same error spectrum under controllers a factor of ten
    apart. An oracle given the corpus' true ratios read 0.855 → 0.943 macro-F1."""
    th = theta + 0.5
    ev: dict[str, float | None] = {
        "process_fit": fit,
        "log_dead_time_samples": math.log10(th),
        "dead_time_share": None if integrating else th / (tau + th),
    }
    gain = abs(K)
    if gain <= 0 or not math.isfinite(gain):
        return ev
    kc_simc = (1.0 if integrating else tau) / (gain * 2.0 * th)
    ti_simc = 8.0 * th if integrating else min(tau, 8.0 * th)
    if kc is not None and kc != 0 and kc_simc > 0:
        ev["kc_over_simc"] = math.log10(abs(kc) / kc_simc)
        ev["loop_gain"] = math.log10(abs(kc) * gain * (th if integrating else 1.0))
    if ti_samples is not None and ti_samples > 0 and ti_simc > 0:
        ev["ti_over_simc"] = math.log10(ti_samples / ti_simc)
    return ev
