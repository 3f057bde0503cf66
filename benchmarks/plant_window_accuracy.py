"""The standard chain on windows as running plants give them (issue 25).

Cases from ``simulator.plant_windows.generate_plant_window_cases``: every class with 0-4
set-point steps, output limits at 50-95 %, disturbance periods of 0.5-20 × the loop's ultimate
period, continuous or quantised PV and three noise levels. Prints the confusion matrix, recall,
precision and F1 per class and the macro-F1, then the accuracy per family (set-point steps,
output limit, recording, noise), so a weak family is visible, and how many windows were refused
for set-point steps alone.

``--decision learned``: the learned decision names the cause (``plantcheck diagnose --decision
learned``), ``--model FILE`` another model file than the shipped one. The corpus the decision is
fitted on (``simulator/corpus.py``) is drawn by other code than these windows, so its figures
here are a transfer figure on simulated loops.

``--processes`` draws the same windows on a process table the chain was not developed on
(``simulator.cases.OTHER_PROCESS_SETS``), to show what the figures owe to the benchmark's own
table. There a sticky valve whose stickband lies within the controller output's noise moves
with that noise (a dithered valve shows no stick-slip on SP, PV and OP); the script counts the
sticky windows whose valve moves in more than a tenth of the samples, and how many of them read
`stiction`.

    python benchmarks/plant_window_accuracy.py [--seeds 1 2] [--per-cell 2]
        [--processes benchmark|long-lags|short-dead-times] [-v]
        [--decision rules|learned] [--model FILE]
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections
import time

import numpy as np
from model_option import add_decision_options, decision_params

from plantcheck.diagnosis import diagnose
from plantcheck.simulator.cases import OTHER_PROCESS_SETS
from plantcheck.simulator.loop import simulate_loop
from plantcheck.simulator.plant_windows import CLASSES, generate_plant_window_cases

REFUSED_FOR_SP = "leave no settled stretch"
DITHERED = 0.1
"""A sticky valve that moves in more than this share of the samples follows OP's noise."""


def _f1(tp: int, fp: int, fn: int) -> tuple[float, float, float]:
    recall = tp / (tp + fn) if tp + fn else 0.0
    precision = tp / (tp + fp) if tp + fp else 0.0
    f1 = 2 * recall * precision / (recall + precision) if recall + precision else 0.0
    return recall, precision, f1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--per-cell", type=int, default=2)
    ap.add_argument(
        "--processes", choices=["benchmark", *OTHER_PROCESS_SETS], default="benchmark",
        help="process table (default: the benchmark's, simulator.cases.PROCESSES)",
    )  # fmt: skip
    ap.add_argument("-v", "--verbose", action="store_true", help="list every wrong window")
    add_decision_options(ap)
    args = ap.parse_args()
    params = decision_params(args)
    table = OTHER_PROCESS_SETS.get(args.processes)
    dithered: collections.Counter[bool] = collections.Counter()
    t0 = time.perf_counter()
    confusion: collections.Counter[tuple[str, str]] = collections.Counter()
    family: dict[str, collections.Counter[tuple[str, bool]]] = collections.defaultdict(
        collections.Counter
    )
    refused = 0
    for seed in args.seeds:
        for pc in generate_plant_window_cases(seed, args.per_cell, table):
            c = pc.case
            r = simulate_loop(c.config)
            d = diagnose(r.pv, r.op, c.config.sample_time_s, sp=r.sp, loop_type=c.loop_type,
                         quantify=False, params=params)  # fmt: skip
            if c.cause == "stiction" and np.mean(np.diff(r.mv) != 0.0) > DITHERED:
                dithered[d.cause == "stiction"] += 1
            confusion[(c.cause, d.cause)] += 1
            hit = d.cause == c.cause
            family["set-point steps"][(str(pc.sp_steps), hit)] += 1
            family["output limit"][("below 100 %" if pc.op_limit else "free", hit)] += 1
            family["recording"][(pc.recording, hit)] += 1
            family["noise"][(f"σ {pc.noise:g} %", hit)] += 1
            if d.cause == "insufficient_data" and any(REFUSED_FOR_SP in n for n in d.notes):
                refused += 1
            if args.verbose and not hit:
                print(f"{c.name:70s} -> {d.cause:22s} {'; '.join(d.notes)[:160]}")
    total = sum(confusion.values())
    predicted = sorted({p for _, p in confusion} | set(CLASSES))
    model = f" ({args.model})" if args.model else ""
    print(f"windows: {total} in {time.perf_counter() - t0:.1f} s, decision {args.decision}{model}")
    print("true \\ predicted".ljust(22) + "".join(p[:11].rjust(12) for p in predicted))
    f1s = []
    for cls in CLASSES:
        row = "".join(str(confusion[(cls, p)]).rjust(12) for p in predicted)
        tp = confusion[(cls, cls)]
        fn = sum(confusion[(cls, p)] for p in predicted) - tp
        fp = sum(confusion[(t, cls)] for t in CLASSES) - tp
        recall, precision, f1 = _f1(tp, fp, fn)
        f1s.append(f1)
        print(f"{cls[:21]:22s}{row}   recall {recall:.2f} precision {precision:.2f} F1 {f1:.2f}")
    accuracy = sum(confusion[(c, c)] for c in CLASSES) / total
    print(f"accuracy {accuracy:.3f}, macro-F1 {sum(f1s) / len(f1s):.3f}")
    print(f"refused for set-point steps alone: {refused} of {total}")
    n_dith = dithered[True] + dithered[False]
    print(
        f"sticky windows whose valve moves in more than {DITHERED:.0%} of the samples "
        f"(dithered by OP's noise): {n_dith}, read stiction {dithered[True]}"
    )
    for name, counts in family.items():
        cells = sorted({k for k, _ in counts})
        parts = [
            f"{k}: {counts[(k, True)]}/{counts[(k, True)] + counts[(k, False)]}" for k in cells
        ]
        print(f"{name:16s} " + ", ".join(parts))


if __name__ == "__main__":
    main()
