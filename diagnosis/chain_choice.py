"""Which chain diagnoses a loop: the one rule for every caller (CLI, scheduler, workers).

The advanced chain (methods §7.4) reads the valve from its stem position MV, so it needs MV for
most of the window; with MV for less than ``min_mv_coverage`` of it (a positioner that reports
now and then, a tag mapped but dead) the standard chain judges the loop from SP, PV and OP, and
the note says why (Bacci di Capaci 2016, §2.7: the advanced chain where MV is available).
"""

from __future__ import annotations

import numpy as np

from plantcheck.diagnosis.baseline import Baseline
from plantcheck.diagnosis.chain import ChainParams, diagnose, diagnose_advanced
from plantcheck.diagnosis.result import Diagnosis
from plantcheck.diagnosis.signal_tools import BoolArray, FloatArray

MIN_MV_COVERAGE = 0.5
"""Fewest finite MV samples (fraction of the window) for the advanced chain to run."""


def diagnose_loop(
    pv: FloatArray,
    op: FloatArray,
    ts: float,
    sp: FloatArray | None = None,
    mv: FloatArray | None = None,
    auto: BoolArray | None = None,
    loop_type: str = "other",
    quantify: bool = True,
    min_mv_coverage: float = MIN_MV_COVERAGE,
    params: ChainParams | None = None,
    baseline: Baseline | None = None,
) -> Diagnosis:
    """The advanced chain when MV covers ``min_mv_coverage`` of the window, else the standard
    one (arguments as :func:`diagnose`; MV in % of travel, NaN = gap; ``params`` None: the
    defaults)."""
    coverage = float(np.isfinite(mv).mean()) if mv is not None and mv.size else 0.0
    if mv is not None and coverage >= min_mv_coverage:
        return diagnose_advanced(
            pv, op, mv, ts, sp=sp, auto=auto, loop_type=loop_type, params=params,
            quantify=quantify, baseline=baseline,
        )  # fmt: skip
    d = diagnose(pv, op, ts, sp=sp, auto=auto, loop_type=loop_type, params=params,
                 quantify=quantify, baseline=baseline)  # fmt: skip
    if mv is not None:
        d = d.with_notes_first(
            [
                f"MV recorded for {100 * coverage:.0f} % of the window (the advanced chain "
                f"needs {100 * min_mv_coverage:.0f} %): standard chain"
            ]
        )
    return d
