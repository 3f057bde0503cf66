"""One rule picks the chain (``diagnosis/chain_choice.py``): the advanced chain where the stem
position MV covers half the window, the standard chain otherwise, saying why."""

from __future__ import annotations

import numpy as np

from plantcheck.diagnosis import diagnose_loop
from plantcheck.simulator.cases import sticky_flow_config
from plantcheck.simulator.loop import simulate_loop


def test_the_chain_follows_the_stem_positions_coverage() -> None:
    r = simulate_loop(sticky_flow_config(2000))
    full = diagnose_loop(r.pv, r.op, 1.0, sp=r.sp, mv=r.mv, loop_type="flow", quantify=False)
    assert full.chain == "advanced"

    sparse = r.mv.copy()
    sparse[np.arange(sparse.size) % 10 >= 3] = np.nan  # MV for 30 % of the window
    d = diagnose_loop(r.pv, r.op, 1.0, sp=r.sp, mv=sparse, loop_type="flow", quantify=False)
    assert d.chain == "standard"
    assert d.notes[0].startswith("MV recorded for 30 % of the window")

    none = diagnose_loop(r.pv, r.op, 1.0, sp=r.sp, loop_type="flow", quantify=False)
    assert none.chain == "standard" and not none.notes[0].startswith("MV recorded")
