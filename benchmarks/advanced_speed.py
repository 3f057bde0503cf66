"""Median time of the advanced chain (diagnose_advanced, no quantification) per 3,600-sample
window on one core; target (issue 4): <= 10 ms. Pin with ``taskset -c 0``.

    python benchmarks/advanced_speed.py [--repeat 30]
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace

from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI and the workers do

from plantcheck.diagnosis import diagnose_advanced  # noqa: E402
from plantcheck.service.allocator import tune_allocator  # noqa: E402
from plantcheck.simulator.actuator import ActuatorSpec  # noqa: E402
from plantcheck.simulator.cases import sticky_flow_config  # noqa: E402
from plantcheck.simulator.loop import simulate_loop  # noqa: E402


def main() -> None:
    # as every plantcheck process that diagnoses does (service/allocator.py)
    tune_allocator()
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=30)
    args = ap.parse_args()
    base = replace(sticky_flow_config(3600), mv_noise_std=0.03)
    cases = {
        "sticky valve": replace(base, actuator=ActuatorSpec()),
        "calibration": replace(
            base, valve="linear", actuator=ActuatorSpec("calibration", bias=3.0)
        ),
    }
    for name, cfg in cases.items():
        r = simulate_loop(cfg)
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            d = diagnose_advanced(r.pv, r.op, r.mv, 1.0, sp=r.sp, loop_type="flow", quantify=False)
            times.append(time.perf_counter() - t0)
        med = statistics.median(times) * 1000
        verdict = "OK" if med <= 10.0 else "MISSED"
        print(f"3600 samples, {name}: median {med:.2f} ms (target <= 10 ms) {verdict}; {d.cause}")


if __name__ == "__main__":
    main()
