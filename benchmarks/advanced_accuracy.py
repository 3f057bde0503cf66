"""Advanced chain (with MV) against the standard chain (same records without MV).

Generated actuator cases (simulator.cases.generate_actuator_cases): every actuator class and
healthy valves in aggressive or disturbed loops, four loop types, OP noise 0.05–0.3 %.
Prints, per true cause, how many cases each chain gets right, the confusions, the share of
healthy valves judged ok, and the error of S measured from MV. Targets (issue 4): every class
>= 90 %, healthy valves ok >= 95 %, S from MV within 0.2 % of travel, advanced never less right
than standard.

    python benchmarks/advanced_accuracy.py [--seeds 1 2 ... 8] [--per-cell 3]
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections

import numpy as np

from plantcheck.diagnosis import diagnose, diagnose_advanced
from plantcheck.simulator.cases import generate_actuator_cases
from plantcheck.simulator.loop import simulate_loop


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6, 7, 8])
    ap.add_argument("--per-cell", type=int, default=3)
    args = ap.parse_args()
    adv: collections.Counter[tuple[str, str]] = collections.Counter()
    std: collections.Counter[tuple[str, str]] = collections.Counter()
    healthy = healthy_ok = 0
    s_err: list[float] = []
    worse: list[str] = []
    for seed in args.seeds:
        for c in generate_actuator_cases(seed=seed, per_cell=args.per_cell):
            r = simulate_loop(c.config)
            ts = c.config.sample_time_s
            d = diagnose_advanced(
                r.pv, r.op, r.mv, ts, sp=r.sp, loop_type=c.loop_type, quantify=False
            )
            s = diagnose(r.pv, r.op, ts, sp=r.sp, loop_type=c.loop_type, quantify=False)
            adv[(c.cause, d.cause)] += 1
            std[(c.cause, s.cause)] += 1
            if s.cause == c.cause != d.cause:
                worse.append(f"{c.name} (seed {seed}): standard {s.cause}, advanced {d.cause}")
            if c.valve_state == "ok":
                healthy += 1
                healthy_ok += d.valve is not None and d.valve.state == "ok"
            if c.valve_state == "stiction" and d.cause == "stiction" and c.S is not None:
                s_est = d.stiction.S
                if s_est is not None:
                    s_err.append(abs(float(s_est) - c.S))
    print(f"{'true cause':22s} {'advanced':>9s} {'standard':>9s}  advanced confusions")
    for a in sorted({a for a, _ in adv}):
        n = sum(v for (x, _), v in adv.items() if x == a)
        wrong = {b: v for (x, b), v in adv.items() if x == a and b != a}
        print(f"{a:22s} {adv[(a, a)] / n:9.2f} {std[(a, a)] / n:9.2f}  {wrong}")
    print(
        f"healthy valves judged ok: {healthy_ok} of {healthy} ({healthy_ok / max(1, healthy):.2f})"
    )
    print(f"records the advanced chain gets wrong and the standard right: {len(worse)}")
    for line in worse:
        print(f"  {line}")
    if s_err:
        print(
            f"S from MV: median |error| {np.median(s_err):.2f} %, 90th percentile "
            f"{np.percentile(s_err, 90):.2f} % of travel (n = {len(s_err)})"
        )
    predicted = sorted({b for _, b in adv})
    print("\nadvanced chain, true cause (rows) x predicted (columns):")
    print(" " * 22 + " ".join(f"{b[:9]:>9s}" for b in predicted))
    for a in sorted({a for a, _ in adv}):
        print(f"{a:22s}" + " ".join(f"{adv[(a, b)]:9d}" for b in predicted))


if __name__ == "__main__":
    main()
