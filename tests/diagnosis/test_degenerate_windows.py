"""Windows no plant should send and some historians do: a frozen or missing PV, straight
lines interpolated across a gap, a clamped OP, a square wave, a PV on a coarse grid. The
chain answers each with a diagnosis (a data-quality verdict where nothing can be judged),
never an exception: two such windows once stopped it (a singular matrix in the controller
change search, a square root of a negative rounding residue in the identification)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.chain import diagnose_advanced
from plantcheck.diagnosis.result import CAUSES


def _signals(n: int) -> Iterator[tuple[str, np.ndarray]]:
    t = np.arange(n, dtype=np.float64)
    rng = np.random.default_rng(n)
    yield "constant", np.full(n, 42.0)
    yield "ramp", 40.0 + 0.01 * t
    yield "step", np.where(t < n // 2, 40.0, 45.0)
    yield "walk", 50.0 + np.cumsum(rng.normal(size=n)) * 0.05
    yield "coarse grid", np.round(42.0 + 0.3 * rng.normal(size=n))
    yield "square", 42.0 + np.sign(np.sin(t / 20.0))
    yield "half missing", np.where(t < n // 2, np.nan, 42.0 + rng.normal(size=n))
    yield "at 100 %", np.full(n, 100.0)


@pytest.mark.parametrize("n", [150, 3600])
def test_degenerate_windows_get_a_diagnosis(n: int) -> None:
    signals = dict(_signals(n))
    for (pv_kind, pv), (op_kind, op) in [(a, b) for a in signals.items() for b in signals.items()]:
        for sp in (None, np.full(n, 45.0)):
            d = diagnose(pv, op, 1.0, sp=sp, loop_type="flow", quantify=False)
            assert d.cause in CAUSES, (pv_kind, op_kind, d.cause)
            d.to_dict()
        mv = signals["constant"]
        assert diagnose_advanced(pv, op, mv, 1.0, loop_type="flow", quantify=False).cause in CAUSES
