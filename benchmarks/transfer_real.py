"""Transfer figures (issue 46): the rules and the learned decision on real records that no
threshold, feature or model was chosen on. Test sets only: read the figures, never tune on them.

- ISDB, 14 loops (Jelali & Huang 2010) with their comment labels: right answers per label as in
  tests/isdb.py; the standard chain, loop types from the descriptions.
- Tennessee Eastman (Downs & Vogel 1993; Braatz data): the reactor temperature XMEAS(9) and
  its cooling-water flow XMV(10), 3-min samples, test files from the fault's start (sample
  160): d00 normal, d04 and d11 cooling-water temperature step and random variation, d14 the
  cooling-water valve sticking, d15 the condenser's (nearly invisible in this data).

The refinery set has its own scorer: ``python3 ../shared/tools/score_real.py stiction -- CMD``
(``CMD ... --decision learned`` for the learned decision).

    python benchmarks/transfer_real.py [--model FILE]

``--model FILE``: read with another model file than the shipped one (``plantcheck model fit
--out FILE``, say with ``--tree-seed``: how far one fit's readings of these records are a draw).
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from isdb import ACCEPTED, SHARED, load_isdb
from model_option import chosen_model

from plantcheck.diagnosis import Baseline, ChainParams, baseline_from, diagnose

TEP = SHARED / "data" / "tep-braatz"
TEP_FILES = {"d00": "normal", "d04": "IDV(4) step", "d11": "IDV(11) random",
             "d14": "IDV(14) valve sticking", "d15": "IDV(15) condenser valve"}  # fmt: skip


def tep_loop(name: str) -> tuple[np.ndarray, np.ndarray]:
    """PV (reactor temperature, °C) and OP (cooling-water flow, %) from the fault's start."""
    data = np.loadtxt(TEP / f"{name}_te.dat")
    return data[160:, 8], data[160:, 50]


def tep_baseline() -> Baseline:
    """The loop's normal from the training file of normal operation (d00.dat, stored
    transposed: 52 rows of 500 samples), apart from the test records."""
    data = np.loadtxt(TEP / "d00.dat")
    return baseline_from(data[8], data[50], source="d00.dat")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=Path, help="model file (default: the shipped one)")
    args = ap.parse_args()
    model = chosen_model(args.model)
    rules = ChainParams(decide_by="rules", cause_model=model)
    learned = ChainParams(decide_by="learned", cause_model=model)
    loops = load_isdb()
    if not loops:
        print("ISDB: ../shared/data absent, skipped")
    else:
        right = {"rules": 0, "learned": 0}
        print(f"ISDB {len(loops)} loops: name, label, rules, learned (p)")
        labelled = 0
        for lp in loops:
            out = {}
            for name, params in (("rules", rules), ("learned", learned)):
                d = diagnose(lp.pv, lp.op, lp.ts, loop_type=lp.loop_type, params=params,
                             quantify=False)  # fmt: skip
                out[name] = d
                ok = lp.label in ACCEPTED and d.cause in ACCEPTED[lp.label]
                right[name] += ok
            labelled += lp.label in ACCEPTED
            p = out["learned"].confidence
            print(f"  {lp.name:10s} {lp.label:22s} {out['rules'].cause:22s} "
                  f"{out['learned'].cause:22s} ({p:.2f})")  # fmt: skip
        print(f"ISDB right of {labelled} labelled: rules {right['rules']}, "
              f"learned {right['learned']}")  # fmt: skip
    if not TEP.is_dir():
        print("Tennessee Eastman: ../shared/data/tep-braatz absent, skipped")
        return
    print("Tennessee Eastman reactor temperature loop (XMEAS 9 / XMV 10), 800 samples at 180 s;")
    print("rules, learned, then each with the baseline from d00.dat:")
    normal = tep_baseline()
    for name, what in TEP_FILES.items():
        pv, op = tep_loop(name)
        cells = []
        for base in (None, normal):
            for params in (rules, learned):
                d = diagnose(pv, op, 180.0, loop_type="temperature", params=params,
                             quantify=False, baseline=base)  # fmt: skip
                cells.append(f"{d.cause} ({d.confidence:.2f})")
        ratio = d.indices.get("variability_ratio") or 0.0
        print(f"  {name} {what:24s} error σ {ratio:5.1f} x baseline: " + ", ".join(cells))


if __name__ == "__main__":
    main()
