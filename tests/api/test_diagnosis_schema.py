"""The API's model of the diagnosis JSON (``api/diagnosis_schema.py``) takes what the chains
write, field for field, so ``/openapi.json`` describes the object clients read."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from plantcheck.api.diagnosis_schema import DiagnosisJSON
from plantcheck.diagnosis import diagnose, diagnose_loop
from plantcheck.simulator.cases import sticky_flow_config
from plantcheck.simulator.loop import simulate_loop


def _payloads() -> list[dict[str, Any]]:
    r = simulate_loop(sticky_flow_config(2000))
    flat = np.full(2000, 50.0)
    return [
        diagnose(r.pv, r.op, 1.0, sp=r.sp, loop_type="flow").to_dict(),  # quantified stiction
        diagnose_loop(r.pv, r.op, 1.0, sp=r.sp, mv=r.mv, loop_type="flow").to_dict(),  # advanced
        diagnose(flat, r.op, 1.0, loop_type="flow").to_dict(),  # data_quality
        diagnose(r.pv[:100], r.op[:100], 1.0).to_dict(),  # insufficient_data
    ]


@pytest.mark.parametrize("payload", _payloads(), ids=["stiction", "advanced", "frozen", "short"])
def test_every_stored_field_is_described(payload: dict[str, Any]) -> None:
    model = DiagnosisJSON.model_validate(payload)
    assert model.model_dump(by_alias=True, exclude_unset=True) == payload
    assert not model.model_extra  # nothing the schema does not name
    for part in (model.stiction, model.oscillation, model.valve):
        assert part is None or not part.model_extra, part
