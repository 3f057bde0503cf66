"""Stiction on the windows real plants give: two hours at 10 s of slow loops (issue 24).

The family ``simulator.cases.generate_short_window_cases``: τ 40–300 s or a level with a detuned
PI, and flows of τ 2–8 s with a slow integral (the refinery records' kind); 0–3 set-point steps,
drifting loads, three noise levels, continuous / quantised / compressed PV; sticky valves with
one to three stick-slip events and their healthy twins. Prints, per kind (slow, flow), noise
level and recording, the stiction recall and the false alarms on the healthy twins, then
how many detected sticky windows got a size (``stiction.estimate``) and its error per method.

``--decision learned``: the learned decision names the cause (``plantcheck diagnose --decision
learned``), ``--model FILE`` another model file than the shipped one. The corpus the decision is
fitted on (``simulator/corpus.py``) holds no window of this family as such, so its figures here
are a transfer figure on simulated loops, as the real records' are on plant ones.

    python benchmarks/short_window_accuracy.py [--seeds 1 2] [--per-cell 4] [-v]
        [--decision rules|learned] [--model FILE]
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections
import statistics
import time

from model_option import add_decision_options, decision_params

from plantcheck.diagnosis import diagnose
from plantcheck.simulator.cases import generate_short_window_cases
from plantcheck.simulator.loop import simulate_loop


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--per-cell", type=int, default=4)
    ap.add_argument("-v", "--verbose", action="store_true", help="list every wrong window")
    add_decision_options(ap)
    args = ap.parse_args()
    params = decision_params(args)
    t0 = time.perf_counter()
    found: collections.Counter[tuple[str, str, bool]] = collections.Counter()
    errors: dict[str, list[float]] = collections.defaultdict(list)
    sized = detected = 0
    for seed in args.seeds:
        for c in generate_short_window_cases(seed=seed, per_cell=args.per_cell):
            r = simulate_loop(c.config)
            d = diagnose(
                r.pv, r.op, c.config.sample_time_s, sp=r.sp, loop_type=c.loop_type, params=params
            )
            # e.g. "slow 0.2-quantised": the slow loops and the flows apart
            cell = c.name.split("-noise")[1].split("-r")[0]
            cell = ("flow " if c.loop_type == "flow" else "slow ") + cell
            hit = d.cause == "stiction"
            found[(c.cause, cell, hit)] += 1
            if args.verbose and hit != (c.cause == "stiction"):
                print(f"  {c.name:75s} -> {d.cause:22s} {d.notes[-1][:60] if d.notes else ''}")
            if c.cause == "stiction" and hit:
                detected += 1
                est = d.stiction.estimate
                if est is not None and est.S is not None:
                    sized += 1
                    errors[est.method].append(abs(est.S - c.config.S))
    cells = sorted({cell for _, cell, _ in found})
    print(
        f"short-window family: seeds {args.seeds}, decision {args.decision}"
        f"{'' if args.model is None else f' ({args.model})'}, {time.perf_counter() - t0:.0f} s"
    )
    print(f"{'noise-recording':22s} {'recall':>12s} {'false alarms':>14s}")
    totals = collections.Counter()
    for cell in cells:
        tp, fn = found[("stiction", cell, True)], found[("stiction", cell, False)]
        fp, tn = found[("ok", cell, True)], found[("ok", cell, False)]
        totals.update({"tp": tp, "fn": fn, "fp": fp, "tn": tn})
        print(f"{cell:22s} {tp:5d}/{tp + fn:<6d} {fp:7d}/{fp + tn:<6d}")
    tp, fn, fp, tn = totals["tp"], totals["fn"], totals["fp"], totals["tn"]
    print(
        f"{'all':22s} {tp:5d}/{tp + fn:<6d} {fp:7d}/{fp + tn:<6d}  "
        f"recall {tp / max(tp + fn, 1):.2f}, false alarms {fp / max(fp + tn, 1):.1%}"
    )
    print(f"sized: {sized} of {detected} detected sticky windows ({sized / max(detected, 1):.0%})")
    for method, errs in sorted(errors.items()):
        print(
            f"  {method:12s} {len(errs):3d} estimates, median |S error| "
            f"{statistics.median(errs):.2f} % of travel"
        )


if __name__ == "__main__":
    main()
