"""The proposal in the control system's form (issue 48 item 3), against a table computed by
hand: Kc = 2 % of OP per PV unit, Ti = 120 s on a PV of 50 units' span (Kc_n = 1 %/%);
the series PID Kc' = 1.6, Ti' = 80 s, Td' = 20 s is the ideal Kc = 2, Ti = 100 s, Td = 16 s
(Kc = Kc'(1 + Td'/Ti'), Ti = Ti' + Td', Td = Ti'Td'/(Ti' + Td'))."""

from __future__ import annotations

import pytest

from plantcheck.diagnosis.controller_forms import (
    ControllerForm,
    ideal_to_series,
    in_dcs_form,
    series_to_ideal,
)

TABLE = [
    # form, gain, integral, pv_span -> gain, gain unit, integral, integral unit
    ("ideal", "gain", "seconds", None, 2.0, "% OP per PV unit", 120.0, "s"),
    ("ideal", "gain", "seconds", 50.0, 1.0, "% OP per % of span", 120.0, "s"),
    ("ideal", "proportional_band", "minutes", 50.0, 100.0, "% (proportional band)", 2.0, "min"),
    ("ideal", "gain", "repeats_per_minute", 50.0, 1.0, "% OP per % of span", 0.5, "repeats/min"),
    ("series", "proportional_band", "seconds", 25.0, 200.0, "% (proportional band)", 120.0, "s"),
    ("parallel", "gain", "seconds", None, 2.0, "% OP per PV unit", 2.0 / 120.0, "per s"),
    ("parallel", "gain", "minutes", 50.0, 1.0, "% OP per % of span", 0.5, "per min"),
]


@pytest.mark.parametrize(("form", "gain", "integral", "span", "g", "g_unit", "i", "i_unit"), TABLE)
def test_pi_forms_match_the_hand_table(
    form: str, gain: str, integral: str, span: float | None,
    g: float, g_unit: str, i: float, i_unit: str,
) -> None:  # fmt: skip
    f = ControllerForm(form=form, gain=gain, integral=integral, pv_span=span)  # type: ignore[arg-type]
    s = in_dcs_form(2.0, 120.0, 0.0, f)
    assert (s.gain, s.gain_unit, s.integral_unit) == (pytest.approx(g), g_unit, i_unit)
    assert s.integral == pytest.approx(i)
    assert s.action == "reverse" and s.derivative is None


def test_series_and_ideal_pid_convert_both_ways() -> None:
    assert ideal_to_series(2.0, 100.0, 16.0) == pytest.approx((1.6, 80.0, 20.0))
    assert series_to_ideal(1.6, 80.0, 20.0) == pytest.approx((2.0, 100.0, 16.0))
    with pytest.raises(ValueError, match="Ti < 4"):
        ideal_to_series(2.0, 50.0, 16.0)


def test_action_is_the_sign_and_a_contradiction_is_noted() -> None:
    direct = in_dcs_form(-0.5, 30.0, 0.0, ControllerForm(action="reverse"))
    assert direct.gain == pytest.approx(0.5) and direct.action == "direct"
    assert "configuration says reverse" in direct.note
    assert "direct acting (ideal form)" in direct.text()


def test_a_band_without_the_span_is_refused() -> None:
    with pytest.raises(ValueError, match="pv_span"):
        in_dcs_form(1.0, 10.0, 0.0, ControllerForm(gain="proportional_band"))
