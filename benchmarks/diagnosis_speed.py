"""Median time of the whole standard chain (plantcheck.diagnosis.diagnose) on one core.

Windows of 3,600 and 86,400 samples (1 h and 1 day at 1 s) of a sticky flow loop, which runs
every stage: window checks, oscillation, all stiction tests and the vote. Targets (issue 2):
<= 10 ms and <= 200 ms for the detection chain. The same window with the S/J quantification
(issue 3, Hammerstein grid search) is printed beside it, and the 3,600-sample window with four
set-point steps (issue 25: <= 10 ms). Pin to one core with ``taskset -c 0``.

``--stages`` also prints what the chain's main steps take inside it, on the 3,600-sample
window: each step the chain module calls is timed where it calls it (its median per window),
so a step's cost includes the caches the steps before it left cold, which a step timed alone
does not show (the learned decision's trees: 0.4 ms alone, 1.4 ms in the chain before their
walk was laid out level by level).

    python benchmarks/diagnosis_speed.py [--repeat 30] [--stages]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI and the workers do

from machine_speed import machine_line  # noqa: E402

import plantcheck.diagnosis.chain as chain_module  # noqa: E402
from plantcheck.diagnosis import diagnose  # noqa: E402
from plantcheck.service.allocator import tune_allocator  # noqa: E402
from plantcheck.simulator.cases import sticky_flow_config  # noqa: E402
from plantcheck.simulator.loop import simulate_loop  # noqa: E402


def window(n: int, sp_steps: int = 0) -> tuple[object, ...]:
    cfg = sticky_flow_config(n)
    if sp_steps:
        gap = n * cfg.sample_time_s / (sp_steps + 1)
        levels = [52.0, 49.0, 53.0, 50.0, 51.0]
        steps = tuple(((k + 1) * gap, levels[k % 5]) for k in range(sp_steps))
        cfg = replace(cfg, sp_steps=steps)
    r = simulate_loop(cfg)
    return r.pv, r.op, r.sp


def _median_ms(pv: object, op: object, sp: object, quantify: bool, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        diagnose(pv, op, 1.0, sp=sp, loop_type="flow", quantify=quantify)  # type: ignore[arg-type]
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1000


STAGES = (
    "latest_controller_change",
    "check_window",
    "identify_pi",
    "detect_stick_slip",
    "detect_oscillation",
    "run_stiction_tests",
    "quick_process_fit",
    "decide",
    "window_kpis",
)
"""The chain module's calls timed by ``--stages``."""


def stage_times(pv: object, op: object, sp: object, repeat: int) -> dict[str, float]:
    """Median ms per window of each of ``STAGES`` as the chain calls it."""
    spent: dict[str, list[float]] = defaultdict(list)
    originals = {name: getattr(chain_module, name) for name in STAGES}

    def timed(name: str, f: Callable[..., Any]) -> Callable[..., Any]:
        def call(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return f(*args, **kwargs)
            finally:
                spent[name][-1] += time.perf_counter() - t0

        return call

    try:
        for name, f in originals.items():
            setattr(chain_module, name, timed(name, f))
        for _ in range(repeat):
            for name in STAGES:
                spent[name].append(0.0)
            diagnose(pv, op, 1.0, sp=sp, loop_type="flow", quantify=False)  # type: ignore[arg-type]
    finally:
        for name, f in originals.items():
            setattr(chain_module, name, f)
    return {name: statistics.median(spent[name]) * 1000 for name in STAGES}


def main() -> None:
    # as every plantcheck process that diagnoses does (service/allocator.py)
    tune_allocator()
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--stages", action="store_true", help="time the chain's main steps too")
    args = ap.parse_args()
    print(f"cpu affinity: {sorted(os.sched_getaffinity(0))}")
    print(machine_line(), flush=True)
    for n, target_ms in ((3600, 10.0), (86400, 200.0)):
        pv, op, sp = window(n)
        for quantify in (False, True):
            d = diagnose(pv, op, 1.0, sp=sp, loop_type="flow", quantify=quantify)  # type: ignore[arg-type]
            med = _median_ms(
                pv, op, sp, quantify, args.repeat if not quantify else max(3, args.repeat // 10)
            )
            what = "chain + S/J quantification" if quantify else "detection chain"
            target = (
                ""
                if quantify
                else f"  target <= {target_ms:g} ms " + ("OK" if med <= target_ms else "MISSED")
            )
            print(f"{n:6d} samples, {what:27s}: median {med:8.2f} ms{target}  cause={d.cause}")
    pv, op, sp = window(3600, sp_steps=4)
    d = diagnose(pv, op, 1.0, sp=sp, loop_type="flow", quantify=False)  # type: ignore[arg-type]
    med = _median_ms(pv, op, sp, False, args.repeat)
    verdict = "OK" if med <= 10.0 else "MISSED"
    print(
        f"  3600 samples, 4 set-point steps         : median {med:8.2f} ms  target <= 10 ms "
        f"{verdict}  cause={d.cause}"
    )
    if args.stages:
        pv, op, sp = window(3600)
        print("inside the chain, 3600 samples (median ms per window):")
        for name, ms in stage_times(pv, op, sp, args.repeat).items():
            print(f"  {name:26s} {ms:7.2f}")


if __name__ == "__main__":
    main()
