"""A PI setting for a loop whose tuning is wrong, and what it will do (issue 48 items 2 and 4).

From the identified process model (``identification.py``):

- **SIMC** PI (Skogestad 2003): Kc = τ/(K(τc + θ)), Ti = min(τ, 4(τc + θ)) for a first order
  plus dead time; Kc = 1/(K'(τc + θ)), Ti = 4(τc + θ) for an integrator plus dead time. The
  closed-loop time constant τc is SIMC's "tight but robust" τc = θ, never under two samples,
  and three times looser for level loops under averaging control (absorbing inflow changes
  is their job; Shinskey 1996), unless the loop is configured for tight level control (a
  boiler drum, a reactor's level: ``level_control = "tight"``). The model is taken at its
  cautious edge (gain and dead time two standard deviations up, time constant two down), so
  an uncertain model gets a gentler setting rather than a risky one; the integral time keeps
  the nominal τ (a shorter one would be the bolder setting).
- **Lambda** tuning, the alternative (Dahlin 1968; the pulp-and-paper practice): Kc =
  τ/(K(λ + θ)), Ti = τ with λ = max(τ, 3θ) (for an integrator, Ti = 2λ + θ and
  Kc = Ti/(K'(λ + θ)²)).

PID is not proposed: a first-order model with dead time carries no second lag for a
derivative to cancel, and on such a process SIMC's PI loses little (Skogestad 2003, §4).

The prediction simulates the model under the present and the proposed controller: a unit
set-point step and a load step at the process input that would move an open-loop PV by one
unit, the integral of the absolute error (IAE) of both, and the robustness margins from the
loop's frequency response: maximum sensitivity Ms, gain margin and phase margin (Åström &
Hägglund 2006, §4). A half sample of dead time stands for the zero-order hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from plantcheck.diagnosis.identification import ProcessModel
from plantcheck.diagnosis.signal_tools import log_grid


@dataclass(frozen=True)
class RetuneParams:
    """How a proposal is chosen."""

    tau_c_over_theta: float = 1.0
    """SIMC's τc / θ: 1 is its tight but robust choice (Skogestad 2003)."""
    level_tau_c_over_theta: float = 3.0
    """τc / θ for level loops under averaging control: loose on purpose."""
    level_control: Literal["averaging", "tight"] = "averaging"
    """A level loop's job: averaging (a surge volume evens out the flow it passes on) or
    tight (the level itself matters): SIMC's τc / θ as for any other loop."""
    min_tau_c_samples: float = 2.0
    """τc is at least this many samples (a dead time of a sample or less leaves no margin for
    the sampling itself)."""
    caution_sd: float = 2.0
    """The model is taken this many standard deviations towards the risky side."""
    min_improvement: float = 0.2
    """A proposal must cut the error integral by this share, or the present tuning stays."""
    min_gain_margin: float = 1.7
    """A present tuning with a smaller gain margin on the model is replaced whatever its error
    integral (Åström & Hägglund 2006: GM 2-5 and Ms 1.2-2 are the usual targets)."""
    max_ms: float = 2.0
    """... and one with a larger maximum sensitivity."""
    horizon_settling: float = 12.0
    """The predicted responses run this many times (τ + θ + Ti) long."""
    steps: int = 300
    """Samples of each predicted response at least ..."""
    max_steps: int = 4096
    """... and at most: as many as a quarter of the dead time (or of the sample time, when
    longer) takes over the horizon."""


@dataclass(frozen=True)
class PISetting:
    """An ideal-form PI(D) controller: Kc in % of OP per PV unit (positive: reverse acting,
    OP rises as PV falls below SP), Ti and Td in seconds; ``method`` and τc (s) for a
    proposal."""

    Kc: float
    Ti_s: float
    Td_s: float = 0.0
    method: str = "present"
    tau_c_s: float | None = None

    def to_json(self) -> dict[str, object]:
        out: dict[str, object] = {"Kc": _r(self.Kc), "Ti_s": _r(self.Ti_s)}
        if self.method != "present":
            out |= {"Td_s": _r(self.Td_s), "method": self.method, "tau_c_s": _r(self.tau_c_s)}
        return out


def _r(x: float | None) -> float | None:
    return None if x is None else float(f"{x:.3g}")


@dataclass(frozen=True)
class Robustness:
    """Margins of a loop: gain margin (times; inf when the phase never reaches −180°), phase
    margin (degrees) and maximum sensitivity Ms."""

    gain_margin: float
    phase_margin_deg: float
    ms: float


@dataclass(frozen=True)
class Prediction:
    """The model's closed loop under one controller: IAE (PV units · s) after a unit
    set-point step and after a load step of one PV unit's worth, the margins, and the two
    responses (PV, sampled at ``t_s``) for the plot."""

    iae_sp: float
    iae_load: float
    robustness: Robustness
    t_s: np.ndarray
    pv_sp: np.ndarray
    pv_load: np.ndarray

    @property
    def iae(self) -> float:
        return self.iae_sp + self.iae_load


def _loop(model: ProcessModel, c: PISetting, w: np.ndarray, ts: float) -> np.ndarray:
    """L(jω) of the controller and the model, with half a sample for the hold."""
    s = 1j * w
    K = float(model.K or 0.0)
    theta = float(model.theta_s or 0.0) + ts / 2.0
    g = K / s if model.kind == "ipdt" else K / (float(model.tau_s or 0.0) * s + 1.0)
    return np.asarray(c.Kc * (1.0 + 1.0 / (c.Ti_s * s) + c.Td_s * s) * g * np.exp(-s * theta))


def robustness(model: ProcessModel, c: PISetting, ts: float) -> Robustness:
    """Gain and phase margins and Ms of the loop (model and controller)."""
    scale = float(model.tau_s or 0.0) + float(model.theta_s or 0.0) + c.Ti_s
    w = log_grid(1e-3 / scale, math.pi / ts, 800)
    L = _loop(model, c, w, ts)
    ms = float(np.max(1.0 / np.abs(1.0 + L)))
    phase = np.unwrap(np.angle(L))
    # the unwrapped phase starts near -90° (integral action) or -180° (with an integrator)
    below = np.flatnonzero(phase <= -math.pi)
    if model.kind == "ipdt":
        below = below[below > np.argmax(phase)]
    gm = float(1.0 / np.abs(L[below[0]])) if below.size else math.inf
    cross = np.flatnonzero(np.abs(L) <= 1.0)
    pm = float(180.0 + np.degrees(phase[cross[0]])) if cross.size else 180.0
    return Robustness(gm, pm, ms)


def sensitivity(
    model: ProcessModel, c: PISetting, ts: float, points: int = 60
) -> tuple[np.ndarray, np.ndarray]:
    """(ω in rad/s, |S(jω)|) of the loop, S = 1/(1 + L), log-spaced up to the Nyquist
    frequency: the margins plot; its peak is Ms, and |S| > 1 where the loop amplifies a
    disturbance instead of rejecting it (Åström & Hägglund 2006, section 4.4)."""
    scale = float(model.tau_s or 0.0) + float(model.theta_s or 0.0) + c.Ti_s
    w = log_grid(1e-2 / scale, math.pi / ts, points)
    return w, np.abs(1.0 / (1.0 + _loop(model, c, w, ts)))


def _respond(model: ProcessModel, c: PISetting, dt: float, steps: int, load: float) -> np.ndarray:
    """PV of the closed loop (model + controller, sampled every ``dt``) after a unit
    set-point step (``load`` 0) or a load step of ``load`` % of OP at the process input.

    The loop at step k: e = SP − y, I += ki·e, v = kc·e + I + load, and the process answers
    v of d steps ago, y ← a·y + b·v(k − d). Its state s = (y, I, v(k−1) … v(k−d), 1) moves by
    one matrix, s(k+1) = A·s(k), so the response is the first row of A^k·s(0), k < ``steps``:
    the powers are taken by doubling (log2(steps) matrix products instead of a step-by-step
    loop; a loop past its stability limit overflows to inf, which ``_stable`` reads)."""
    K = float(model.K or 0.0)
    tau = float(model.tau_s or 0.0)
    if model.kind == "ipdt":
        a, b = 1.0, K * dt
    else:
        a = math.exp(-dt / tau) if tau > 0 else 0.0
        b = (1.0 - a) * K
    d = round(float(model.theta_s or 0.0) / dt) + 1
    sp = 0.0 if load else 1.0
    kc, ki = c.Kc, c.Kc * dt / c.Ti_s
    n = d + 3  # y, I, v(k-1) ... v(k-d), the constant 1
    A = np.zeros((n, n))
    A[0, 0], A[0, d + 1] = a, b
    A[1, 0], A[1, 1], A[1, -1] = -ki, 1.0, ki * sp
    A[2, 0], A[2, 1], A[2, -1] = -(kc + ki), 1.0, (kc + ki) * sp + load
    A[np.arange(3, d + 2), np.arange(2, d + 1)] = 1.0
    A[-1, -1] = 1.0
    states = np.zeros((n, 1))
    states[-1, 0] = 1.0
    power = A
    with np.errstate(over="ignore", invalid="ignore"):
        while states.shape[1] < steps:
            states = np.concatenate([states, power @ states], axis=1)
            power = power @ power
    return np.asarray(states[0, :steps])


def predict(model: ProcessModel, c: PISetting, ts: float, params: RetuneParams) -> Prediction:
    """The model's closed loop under ``c``: responses, IAE and margins."""
    slow = float(model.tau_s or 0.0) + float(model.theta_s or 0.0) + c.Ti_s
    horizon = params.horizon_settling * slow
    # the step must resolve the dead time: a lag-dominant loop (τ 47 s, θ 2.5 s) simulated
    # every 3.9 s had its dead time rounded up to 7.8 s and a robust setting (gain margin
    # 2.8) predicted unstable
    fine = max(float(model.theta_s or 0.0), ts) / 4.0
    dt = max(min(horizon / params.steps, fine), horizon / params.max_steps)
    steps = math.ceil(horizon / dt)
    K = float(model.K or 1.0)
    # a load that would move an open-loop PV by one unit (an integrator: within τ + θ + Ti)
    load = 1.0 / (abs(K) * (slow if model.kind == "ipdt" else 1.0)) * math.copysign(1.0, K)
    pv_sp = _respond(model, c, dt, steps, 0.0)
    pv_load = _respond(model, c, dt, steps, load)
    return Prediction(
        iae_sp=float(np.sum(np.abs(1.0 - pv_sp)) * dt),
        iae_load=float(np.sum(np.abs(pv_load)) * dt),
        robustness=robustness(model, c, ts),
        t_s=np.arange(steps) * dt,
        pv_sp=pv_sp,
        pv_load=pv_load,
    )


def _cautious(model: ProcessModel, caution: float) -> tuple[float, float, float]:
    """|K|, τ and θ at the model's risky edge: gain and dead time up, time constant down."""
    K = abs(float(model.K or 0.0)) + caution * float(model.K_sd or 0.0)
    tau = float(model.tau_s or 0.0)
    tau = max(tau - caution * float(model.tau_sd or 0.0), 0.5 * tau)
    theta = float(model.theta_s or 0.0) + caution * float(model.theta_sd or 0.0)
    return K, tau, theta


def simc(model: ProcessModel, ts: float, loop_type: str, params: RetuneParams) -> PISetting:
    """SIMC PI for the model, at its cautious edge (Skogestad 2003)."""
    K, tau, theta = _cautious(model, params.caution_sd)
    averaging = loop_type == "level" and params.level_control == "averaging"
    ratio = params.level_tau_c_over_theta if averaging else params.tau_c_over_theta
    tau_c = max(ratio * theta, params.min_tau_c_samples * ts)
    sign = math.copysign(1.0, float(model.K or 1.0))
    if model.kind == "ipdt":
        return PISetting(sign / (K * (tau_c + theta)), 4.0 * (tau_c + theta), 0.0, "simc", tau_c)
    kc = tau / (K * (tau_c + theta))
    # the integral time from the nominal τ: a shorter one would be the bolder setting
    ti = min(float(model.tau_s or tau), 4.0 * (tau_c + theta))
    return PISetting(sign * kc, ti, 0.0, "simc", tau_c)


def lambda_tuning(model: ProcessModel, ts: float, params: RetuneParams) -> PISetting:
    """Lambda PI (Dahlin 1968) with λ = max(τ, 3θ): slower and smoother than SIMC."""
    K, tau, theta = _cautious(model, params.caution_sd)
    sign = math.copysign(1.0, float(model.K or 1.0))
    if model.kind == "ipdt":
        lam = max(3.0 * theta, params.min_tau_c_samples * ts)
        ti = 2.0 * lam + theta
        return PISetting(sign * ti / (K * (lam + theta) ** 2), ti, 0.0, "lambda", lam)
    lam = max(tau, 3.0 * theta, params.min_tau_c_samples * ts)
    ti = float(model.tau_s or tau)
    return PISetting(sign * tau / (K * (lam + theta)), ti, 0.0, "lambda", lam)


@dataclass(frozen=True)
class Proposal:
    """What the retuning says: the model, the present controller (None: not identified), the
    proposal and its alternative (None with ``note`` saying why), each with its prediction,
    and the ratio of the proposal's error integral to the present one's."""

    model: ProcessModel
    current: PISetting | None
    proposed: PISetting | None
    alternative: PISetting | None
    current_prediction: Prediction | None
    proposed_prediction: Prediction | None
    note: str

    @property
    def iae_ratio(self) -> float | None:
        cur, new = self.current_prediction, self.proposed_prediction
        if cur is None or new is None or not math.isfinite(cur.iae) or cur.iae <= 0:
            return None
        return new.iae / cur.iae


def propose(
    model: ProcessModel,
    current: PISetting | None,
    ts: float,
    loop_type: str = "other",
    params: RetuneParams | None = None,
    sluggish: bool = False,
) -> Proposal:
    """A SIMC proposal (lambda as the alternative) for the identified ``model``, compared with
    the ``current`` controller; none when the model is missing or the present tuning does as
    well within ``min_improvement``.

    A present tuning with poor margins on the model is replaced whatever its error integral,
    unless the diagnosis called the loop ``sluggish``: the loop's own record then says it is
    slow, not fragile, and margins just past the limit on the model are the model's error (a
    simulated level with Ms 1.84 on its true plant read 2.02 on a model whose gain was 22 %
    high, and was given a setting with 1.5 times the error integral)."""
    p = params or RetuneParams()
    if model.kind is None:
        return Proposal(model, current, None, None, None, None, f"no model: {model.reason}")
    if current is not None and current.Kc * float(model.K or 0.0) < 0:
        # closed-loop data without excitation from outside read the controller's inverse,
        # -1/C, whose gain has the opposite sign (Ljung 1999, §13.4)
        note = (
            "the identified gain's sign contradicts the controller's action: the data show "
            "the controller, not the process (nothing excites the loop from outside), or a "
            "signal's sign is wrong"
        )
        return Proposal(model, current, None, None, None, None, note)
    proposed = simc(model, ts, loop_type, p)
    alternative = lambda_tuning(model, ts, p)
    new = predict(model, proposed, ts, p)
    cur = None
    if current is not None:
        cur = predict(model, current, ts, p)
        if not _stable(cur):
            cur = Prediction(math.inf, math.inf, cur.robustness, cur.t_s, cur.pv_sp, cur.pv_load)
    note = ""
    robust = cur is not None and (
        sluggish
        or (cur.robustness.gain_margin >= p.min_gain_margin and cur.robustness.ms <= p.max_ms)
    )
    if (
        cur is not None
        and robust
        and math.isfinite(cur.iae)
        and new.iae > (1.0 - p.min_improvement) * cur.iae
    ):
        note = (
            f"the present tuning does about as well on the model (error integral "
            f"{new.iae / cur.iae:.2f} times the present one's with SIMC): keep it"
        )
        return Proposal(model, current, None, alternative, cur, new, note)
    return Proposal(model, current, proposed, alternative, cur, new, note)


def _stable(pred: Prediction) -> bool:
    """The model's closed loop settles (a loop past its stability limit grows)."""
    tail = np.abs(pred.pv_sp[-pred.pv_sp.size // 4 :] - 1.0)
    return bool(np.all(np.isfinite(tail)) and tail.max() < 0.5 and pred.robustness.gain_margin > 1)
