"""Tennessee Eastman (Downs & Vogel 1993; Braatz data in ../shared/data/tep-braatz): the reactor
temperature loop with its cooling-water valve sticking (IDV 14) is not ``ok``, normal operation
(d00) and a cooling-water temperature step (IDV 4) are (issue 46's transfer floor). Test data
only: nothing was chosen on it.

The rules alone read d14 as ``ok`` (the chain sees no stiction signature at 3-min samples); a
baseline of the loop's normal operation (d00.dat, apart from the test records) finds it 13.8
times more variable. The learned decision finds it without the baseline.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from plantcheck.diagnosis import ChainParams, baseline_from, diagnose

TEP = Path(__file__).resolve().parents[3] / "shared" / "data" / "tep-braatz"

pytestmark = pytest.mark.skipif(
    not (TEP / "d14_te.dat").is_file(),
    reason=f"Tennessee Eastman records not found at {TEP} (../shared is not beside the repository)",
)


def loop(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Reactor temperature XMEAS(9) and cooling-water flow XMV(10) from the fault's start."""
    data = np.loadtxt(TEP / f"{name}_te.dat")
    return data[160:, 8], data[160:, 50]


@pytest.mark.parametrize("decide_by", ["rules", "learned"])
def test_sticking_cooling_valve_is_not_ok_and_normal_operation_is(decide_by: str) -> None:
    normal = np.loadtxt(TEP / "d00.dat")  # stored transposed: 52 rows of 500 samples
    base = baseline_from(normal[8], normal[50], source="d00.dat")
    params = ChainParams(decide_by=decide_by)
    for name, healthy in (("d00", True), ("d04", True), ("d14", False)):
        pv, op = loop(name)
        for baseline in (base, None) if decide_by == "learned" else (base,):
            d = diagnose(pv, op, 180.0, loop_type="temperature", params=params,
                         quantify=False, baseline=baseline)  # fmt: skip
            assert (d.cause == "ok") == healthy, (name, decide_by, baseline, d.cause, d.notes)
