"""Accuracy of the standard chain: generated labelled loops and the real ISDB loops.

Prints the confusion matrix of the generated case matrix (simulator.cases) and the ISDB
table loop by loop (needs ../shared/data; skipped with a note when absent).

    python benchmarks/diagnosis_accuracy.py [--seeds 1 2] [--lengths 1000 5000 20000] [-v]
        [--decision rules|learned] [--model FILE]

``--decision learned``: the learned decision names the cause (``plantcheck diagnose --decision
learned``), ``--model FILE`` another model file than the shipped one; the generated cases are
then a transfer figure on simulated loops (the corpus is drawn by other code), the ISDB loops
the one ``transfer_real.py`` prints.
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from isdb import ACCEPTED, load_isdb
from model_option import add_decision_options, decision_params

from plantcheck.diagnosis import ChainParams, diagnose
from plantcheck.simulator.cases import generate_cases
from plantcheck.simulator.loop import simulate_loop


def generated(
    seeds: list[int], lengths: tuple[int, ...], verbose: bool, params: ChainParams
) -> float:
    conf: collections.Counter[tuple[str, str]] = collections.Counter()
    t0 = time.perf_counter()
    for seed in seeds:
        for c in generate_cases(seed=seed, lengths=lengths):
            r = simulate_loop(c.config)
            d = diagnose(r.pv, r.op, c.config.sample_time_s, sp=r.sp, loop_type=c.loop_type,
                         quantify=False, params=params)  # fmt: skip
            conf[(c.cause, d.cause)] += 1
            if verbose and d.cause != c.cause:
                o = d.oscillation
                print(
                    f"  {c.name:55s} -> {d.cause:26s} P={(o.period_s if o else None) or 0:7.1f} "
                    f"r={(o.regularity if o else None) or 0:6.2f} {dict(d.stiction.tests)} "
                    f"ii={d.indices.get('idle_index')} | {d.notes[-1][:70] if d.notes else ''}"
                )
    truth = sorted({a for a, _ in conf})
    preds = sorted({b for _, b in conf} | set(truth))
    print(f"generated cases: {sum(conf.values())} in {time.perf_counter() - t0:.1f} s")
    print("true \\ predicted".ljust(22) + "".join(p[:12].rjust(13) for p in preds) + "   recall")
    total_ok = 0
    for a in truth:
        row = [conf[(a, b)] for b in preds]
        n = sum(row)
        total_ok += conf[(a, a)]
        print(a.ljust(22) + "".join(str(v).rjust(13) for v in row) + f"   {conf[(a, a)] / n:6.2f}")
    acc = total_ok / sum(conf.values())
    print(f"overall accuracy {acc:.3f}")
    return acc


def isdb(params: ChainParams) -> None:
    loops = load_isdb()
    if not loops:
        print("ISDB data not found at ../shared/data/isdb-partial-npokhappy: skipped")
        return
    right = labelled = 0
    print(f"{'loop':7s} {'type':11s} {'Ts':>5s} {'label':22s} {'cause':26s} ok  tests")
    for lp in loops:
        d = diagnose(lp.pv, lp.op, lp.ts, loop_type=lp.loop_type, params=params)
        acc = ACCEPTED.get(lp.label)
        good = acc is not None and d.cause in acc
        labelled += acc is not None
        right += good
        mark = "yes" if good else ("no " if acc is not None else " - ")
        print(
            f"{lp.name:7s} {lp.loop_type:11s} {lp.ts:5g} {lp.label or '(none)':22s} "
            f"{d.cause:26s} {mark} {dict(d.stiction.tests)}"
        )
    print(f"ISDB: {right} of {labelled} labelled loops right")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--lengths", type=int, nargs="+", default=[1000, 5000, 20000])
    ap.add_argument("-v", "--verbose", action="store_true")
    add_decision_options(ap)
    args = ap.parse_args()
    params = decision_params(args)
    print(f"decision {args.decision}" + (f" ({args.model})" if args.model else ""))
    generated(args.seeds, tuple(args.lengths), args.verbose, params)
    isdb(params)


if __name__ == "__main__":
    main()
