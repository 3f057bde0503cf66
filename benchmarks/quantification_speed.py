"""Median time of one stiction quantification (full grid and refinement) on one core.

A 3,600-sample window of a sticky flow loop (Kano valve, S = 3 %, J = 1 %). Target (issue 3):
<= 0.5 s. Pin to one core with ``taskset -c 0`` for the official figure.

    python benchmarks/quantification_speed.py [--repeat 10]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI and the workers do

from plantcheck.diagnosis.oscillation import detect_oscillation  # noqa: E402
from plantcheck.diagnosis.quantification import quantify_stiction  # noqa: E402
from plantcheck.service.allocator import tune_allocator  # noqa: E402
from plantcheck.simulator.cases import sticky_flow_config  # noqa: E402
from plantcheck.simulator.loop import simulate_loop  # noqa: E402


def main() -> None:
    # as every plantcheck process that diagnoses does (service/allocator.py)
    tune_allocator()
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=10)
    args = ap.parse_args()
    cfg = sticky_flow_config(3600)
    r = simulate_loop(cfg)
    osc = detect_oscillation(r.sp - r.pv, 1.0)
    q = quantify_stiction(r.op, r.pv, 1.0, osc.period_s)
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        quantify_stiction(r.op, r.pv, 1.0, osc.period_s)
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    print(f"cpu affinity: {sorted(os.sched_getaffinity(0))}")
    print(
        f"3600 samples: median {med:.3f} s per window (target <= 0.5 s) "
        f"{'OK' if med <= 0.5 else 'MISSED'}; S = {q.S_best:.2f} % (true 3), "
        f"J = {q.J_best:.2f} % (true 1), reliable = {q.reliable}"
    )


if __name__ == "__main__":
    main()
