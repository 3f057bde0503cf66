"""The ``tuning`` part of a diagnosis (contracts §2, issue 48): for a loop diagnosed with
aggressive or sluggish tuning, the identified process, the present controller, the proposed
one in the control system's form, and what the change is predicted to do; for a sticky or
faulty valve, why there is no proposal. Pure composition of ``identification``,
``retuning`` and ``controller_forms``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.controller_forms import ControllerForm, DcsSetting, in_dcs_form
from plantcheck.diagnosis.identification import (
    IdentificationParams,
    ProcessModel,
    identify_process,
)
from plantcheck.diagnosis.retuning import (
    PISetting,
    Prediction,
    Proposal,
    RetuneParams,
    Robustness,
    propose,
    sensitivity,
)
from plantcheck.diagnosis.signal_tools import FloatArray, round_significant
from plantcheck.diagnosis.tuning import PIEstimate
from plantcheck.diagnosis.valve_kpis import VALVE_STATES

TUNING_CAUSES = frozenset({"aggressive_tuning", "sluggish_tuning"})
"""Causes that are the controller's: they get a proposal (and the scheduler does not let a
window without tuning evidence clear them)."""
VALVE_CAUSES = frozenset(VALVE_STATES) - {"ok"}
"""Causes that are the valve's or its actuator's: no proposal until it is fixed."""
PLOT_POINTS = 100
"""Points of each predicted response in the JSON (the loop page's plot)."""


@dataclass(frozen=True)
class TuningSettings:
    """What the retuning needs besides the window: the loop's controller form, the
    identification's and the proposal's parameters."""

    form: ControllerForm = field(default_factory=ControllerForm)
    identification: IdentificationParams = field(default_factory=IdentificationParams)
    retune: RetuneParams = field(default_factory=RetuneParams)


@dataclass(frozen=True)
class TuningOut:
    """The JSON object and the words the action text gains (empty: none)."""

    json: dict[str, Any]
    action_text: str


def valve_first(cause: str) -> TuningOut:
    """No proposal while the valve misbehaves."""
    return TuningOut(
        {
            "model": None,
            "current": None,
            "proposed": None,
            "predicted": None,
            "dcs": None,
            "note": f"no tuning proposal: the valve is at fault ({cause}); fix the valve "
            "first, a controller retuned around it only moves the cycle",
        },
        "",
    )


def _plot(pred: Prediction) -> dict[str, list[float]]:
    idx = np.linspace(0, pred.t_s.size - 1, PLOT_POINTS).round().astype(np.int64)
    return {
        "t_s": round_significant(pred.t_s[idx], 4),
        "sp": _decimals(pred.pv_sp[idx]),
        "load": _decimals(pred.pv_load[idx]),
    }


def _margins(rob: Robustness) -> dict[str, float | None]:
    return {
        "gain_margin": round(rob.gain_margin, 2) if np.isfinite(rob.gain_margin) else None,
        "phase_margin_deg": round(rob.phase_margin_deg, 1),
        "ms": round(rob.ms, 2),
    }


def _sensitivity(model: ProcessModel, c: PISetting, ts: float) -> dict[str, list[float]]:
    w, mag = sensitivity(model, c, ts)
    return {"w_rad_s": round_significant(w, 4), "mag": _decimals(mag)}


def _decimals(x: FloatArray) -> list[float]:
    """A plot's values to 4 decimals, for JSON."""
    return [float(v) for v in np.round(x, 4)]


def _predicted(prop: Proposal, model: ProcessModel, ts: float) -> dict[str, Any] | None:
    new, cur = prop.proposed_prediction, prop.current_prediction
    if new is None or prop.proposed is None:
        return None
    out: dict[str, Any] = {
        "iae_ratio": None if prop.iae_ratio is None else round(prop.iae_ratio, 2),
        **_margins(new.robustness),
        "proposed_response": _plot(new),
        "proposed_sensitivity": _sensitivity(model, prop.proposed, ts),
    }
    if cur is not None:
        out["current"] = _margins(cur.robustness)
        if np.isfinite(cur.iae):
            out["current_response"] = _plot(cur)
        if prop.current is not None:
            out["current_sensitivity"] = _sensitivity(model, prop.current, ts)
    return out


def tuning_for(
    cause: str,
    pv: FloatArray,
    op: FloatArray,
    ts: float,
    loop_type: str,
    sp_steps: NDArray[np.int64],
    auto_share: float | None,
    pi: PIEstimate | None,
    settings: TuningSettings | None = None,
) -> TuningOut | None:
    """The ``tuning`` object for a diagnosis of ``cause`` (None: the cause is not about the
    tuning or the valve)."""
    if cause in VALVE_CAUSES:
        return valve_first(cause)
    if cause not in TUNING_CAUSES:
        return None
    s = settings or TuningSettings()
    model = identify_process(
        pv, op, ts, integrating=loop_type == "level", sp_steps=sp_steps,
        auto_share=auto_share, params=s.identification,
    )  # fmt: skip
    current = PISetting(pi.kc, pi.ti_s) if pi is not None and pi.ti_s else None
    prop = propose(model, current, ts, loop_type, s.retune, cause == "sluggish_tuning")
    setting: DcsSetting | None = None
    note = prop.note
    if prop.proposed is not None:
        try:
            setting = in_dcs_form(prop.proposed.Kc, prop.proposed.Ti_s, prop.proposed.Td_s, s.form)
            note = "; ".join(x for x in (note, setting.note) if x)
        except ValueError as exc:
            note = "; ".join(x for x in (note, str(exc)) if x)
    out = {
        "model": model.to_json() if model.kind is not None else None,
        "current": current.to_json() if current is not None else None,
        "proposed": prop.proposed.to_json() if prop.proposed is not None else None,
        "alternative": prop.alternative.to_json() if prop.alternative is not None else None,
        "predicted": _predicted(prop, model, ts),
        "dcs": setting.to_json() if setting is not None else None,
        "note": note or None,
    }
    return TuningOut(out, _action_words(prop, setting))


def _action_words(prop: Proposal, setting: DcsSetting | None) -> str:
    """' Proposed (SIMC): gain 1.2, Ti 45 s, reverse acting (ideal form); error integral
    0.45 times the present one's, gain margin 3.0.' or why there is none."""
    if prop.proposed is None:
        return f" No setting proposed: {prop.note}." if prop.note else ""
    p = prop.proposed
    typed = (
        setting.text()
        if setting is not None
        else f"Kc {p.Kc:.3g} % OP per PV unit, Ti {p.Ti_s:.3g} s (ideal form)"
    )
    words = f" Proposed ({p.method.upper()}): {typed}"
    pred = prop.proposed_prediction
    ratio = prop.iae_ratio
    if ratio is not None:
        words += f"; error integral {ratio:.2f} times the present one's"
    if pred is not None and np.isfinite(pred.robustness.gain_margin):
        words += f", gain margin {pred.robustness.gain_margin:.1f}"
    return words + "."
