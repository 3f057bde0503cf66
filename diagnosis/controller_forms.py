"""A PI(D) setting in the form the control system takes it (issue 48 item 3).

plantcheck computes in the ideal (ISA, non-interacting) form, u = Kc·(e + (1/Ti)∫e dt +
Td·de/dt), e = SP − PV, Kc in % of OP per PV unit, Ti and Td in seconds. Control systems
differ (Åström & Hägglund 2006, §3.4; the vendor manuals):

- the *form*: ideal; *parallel* (independent gains Kp, Ki = Kc/Ti, Kd = Kc·Td); *series*
  (interacting, the pneumatic heritage: Kc' = Kc·(1 + √(1 − 4Td/Ti))/2, Ti' = Ti·(1 +
  √(1 − 4Td/Ti))/2, Td' = Ti·(1 − √(1 − 4Td/Ti))/2, which needs Ti ≥ 4Td; for a PI all three
  coincide);
- the *gain*: a gain, or a proportional band PB = 100/Kc_n %, Kc_n the gain in % of OP per %
  of the PV's span (``pv_span`` PV units are 100 %); with ``pv_span`` known the gain is
  given as Kc_n, the dimensionless gain most systems take, else in % of OP per PV unit;
- the *integral*: seconds or minutes per repeat, or repeats per minute (60/Ti s);
- the *action*: reverse (OP rises when PV falls below SP: positive Kc here) or direct; the
  system takes the gain's magnitude and the action apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

Form = Literal["ideal", "parallel", "series"]
GainUnit = Literal["gain", "proportional_band"]
IntegralUnit = Literal["seconds", "minutes", "repeats_per_minute"]
ControllerAction = Literal["reverse", "direct"]


@dataclass(frozen=True)
class ControllerForm:
    """How one loop's controller takes its settings (the configuration's ``controller``)."""

    form: Form = "ideal"
    gain: GainUnit = "gain"
    integral: IntegralUnit = "seconds"
    action: ControllerAction | None = None
    """As configured; None: as the identified controller acts."""
    pv_span: float | None = None
    """PV units that make 100 % of span: needed for a proportional band."""


@dataclass(frozen=True)
class DcsSetting:
    """The setting as the operator types it: the numbers, their units and the action."""

    form: Form
    gain: float
    gain_unit: str
    integral: float
    integral_unit: str
    derivative: float | None
    derivative_unit: str | None
    action: ControllerAction
    note: str = ""

    def text(self) -> str:
        """One line for the action text: 'gain 1.2, Ti 45 s, reverse' and the like."""
        g = f"PB {self.gain:.3g} %" if self.gain_unit.startswith("%") else f"gain {self.gain:.3g}"
        i_name = {"parallel": "Ki", "series": "Ti", "ideal": "Ti"}[self.form]
        parts = [g, f"{i_name} {self.integral:.3g} {self.integral_unit}"]
        if self.derivative:
            d_name = "Kd" if self.form == "parallel" else "Td"
            parts.append(f"{d_name} {self.derivative:.3g} {self.derivative_unit}")
        return ", ".join(parts) + f", {self.action} acting ({self.form} form)"

    def to_json(self) -> dict[str, object]:
        out: dict[str, object] = {
            "form": self.form,
            "gain": float(f"{self.gain:.3g}"),
            "gain_unit": self.gain_unit,
            "integral": float(f"{self.integral:.3g}"),
            "integral_unit": self.integral_unit,
            "derivative": None if self.derivative is None else float(f"{self.derivative:.3g}"),
            "derivative_unit": self.derivative_unit,
            "action": self.action,
        }
        if self.note:
            out["note"] = self.note
        return out


def ideal_to_series(Kc: float, Ti_s: float, Td_s: float) -> tuple[float, float, float]:
    """Ideal to series (interacting) PID; raises ValueError where Ti < 4Td (no series
    equivalent)."""
    if Td_s <= 0:
        return Kc, Ti_s, 0.0
    disc = 1.0 - 4.0 * Td_s / Ti_s
    if disc < 0:
        raise ValueError("Ti < 4·Td: the setting has no series-form equivalent")
    root = math.sqrt(disc)
    return Kc * (1 + root) / 2, Ti_s * (1 + root) / 2, Ti_s * (1 - root) / 2


def series_to_ideal(Kc: float, Ti_s: float, Td_s: float) -> tuple[float, float, float]:
    """Series (interacting) to ideal PID."""
    if Td_s <= 0:
        return Kc, Ti_s, 0.0
    return Kc * (1 + Td_s / Ti_s), Ti_s + Td_s, Ti_s * Td_s / (Ti_s + Td_s)


def in_dcs_form(Kc: float, Ti_s: float, Td_s: float, form: ControllerForm) -> DcsSetting:
    """The ideal-form setting (Kc % of OP per PV unit, signed; Ti, Td s) in ``form``."""
    action: ControllerAction = "reverse" if Kc >= 0 else "direct"
    note = ""
    if form.action is not None and form.action != action:
        note = (
            f"the configuration says {form.action} acting, but the recorded OP acts "
            f"{action}: check the controller's action or the signals' signs"
        )
    k, ti, td = abs(Kc), Ti_s, Td_s
    if form.form == "series":
        k, ti, td = ideal_to_series(k, ti, td)
    if form.gain == "proportional_band":
        if form.pv_span is None or form.pv_span <= 0:
            raise ValueError("a proportional band needs controller.pv_span (PV units = 100 %)")
        k_n = k * form.pv_span / 100.0  # % of OP per % of span
        gain, gain_unit = 100.0 / k_n, "% (proportional band)"
    elif form.pv_span is not None and form.pv_span > 0:
        k_n = k * form.pv_span / 100.0  # the dimensionless gain control systems take
        gain, gain_unit = k_n, "% OP per % of span"
    else:
        k_n = k
        gain, gain_unit = k, "% OP per PV unit"
    if form.form == "parallel":
        # independent gains on the same base as the proportional one
        per_min = form.integral != "seconds"
        ki = k_n / ti * (60.0 if per_min else 1.0)
        unit = "per min" if per_min else "per s"
        kd = k_n * td / (60.0 if per_min else 1.0) if td else None
        return DcsSetting(
            "parallel", gain, gain_unit, ki, unit, kd, ("min" if per_min else "s") if td else None,
            action, note,
        )  # fmt: skip
    if form.integral == "minutes":
        integral, i_unit = ti / 60.0, "min"
    elif form.integral == "repeats_per_minute":
        integral, i_unit = 60.0 / ti, "repeats/min"
    else:
        integral, i_unit = ti, "s"
    d_min = form.integral != "seconds"
    deriv = (td / 60.0 if d_min else td) if td else None
    return DcsSetting(
        form.form, gain, gain_unit, integral, i_unit, deriv,
        ("min" if d_min else "s") if td else None, action, note,
    )  # fmt: skip
