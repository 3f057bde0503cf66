"""Identification and retuning on simulated loops (issue 48's evidence), printed as figures.

    python benchmarks/retuning_accuracy.py [--cases 60] [--seed 5000]

1. Identification: the share of loops whose gain, time constant and dead time are all within
   20 % of the truth (the dead time the simulator applies, whole samples), for loops with
   set-point steps and for routine operation (none), at three load levels; "no model" counts
   as a miss and is listed apart.
2. Proposals for aggressive and sluggish loops: the share with a proposal; among them the share
   whose true closed loop has a gain margin of at least 1.7 and whose error integral under a
   set-point and a load step is at most 0.7 times the present tuning's. Well-tuned loops: the
   share with no proposal or one that changes that integral by less than 20 %.
3. The cost of identification and proposal, ms per 3,600 samples (median and 95th percentile),
   and ms per window as the service pays it.

The loops are ``simulator/tuning_cases.py``'s; nothing here is tuned on real records.
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import time
from dataclasses import dataclass, fields

import numpy as np

from plantcheck.diagnosis.identification import ProcessModel, identify_process
from plantcheck.diagnosis.retuning import PISetting, RetuneParams, predict, robustness
from plantcheck.diagnosis.tuning import identify_pi
from plantcheck.diagnosis.tuning_proposal import TuningSettings, tuning_for
from plantcheck.simulator.tuning_cases import TuningCase, tuning_case


def _within(case: TuningCase, m: ProcessModel, tol: float = 0.2) -> bool:
    p = case.process
    theta = case.effective_dead_time_s
    ok_k = m.K is not None and abs(m.K / p.K - 1.0) <= tol
    ok_th = m.theta_s is not None and abs(m.theta_s - theta) <= tol * max(theta, case.ts)
    ok_tau = p.kind == "integrating" or (
        m.tau_s is not None and abs(m.tau_s / p.tau_s - 1.0) <= tol
    )
    return bool(ok_k and ok_th and ok_tau)


def identification(n: int, seed: int) -> None:
    print("1. identification within 20 % (K, tau, theta)")
    for steps in (True, False):
        for loads in (0.0, 0.3, 1.0):
            hits = none = 0
            for i in range(n):
                case = tuning_case(seed + i, "good", loads, sp_steps=steps)
                r = case.record
                m = identify_process(
                    r.pv, r.op, case.ts, integrating=case.process.kind == "integrating",
                    sp_steps=case.sp_steps,
                )  # fmt: skip
                none += m.kind is None
                hits += m.kind is not None and _within(case, m)
            what = "set-point steps" if steps else "routine (no steps)"
            print(
                f"   {what:20s} loads x{loads:<4g}: {hits}/{n} within 20 % "
                f"({100 * hits / n:.0f} %), {none} without a model"
            )


@dataclass
class _Tally:
    """Proposals for one tuning and family: made, robust (true GM >= 1.7), better (true
    error integral <= 0.7x), small (within 20 %), out of ``loops``."""

    loops: int = 0
    made: int = 0
    robust: int = 0
    better: int = 0
    small: int = 0


def _judge(case: TuningCase, prop: dict[str, float], tally: _Tally) -> None:
    """Apply the proposal to the true plant and compare it with the present tuning."""
    params = RetuneParams()
    setting = PISetting(prop["Kc"], prop["Ti_s"])
    truth = case.true_model()
    present = PISetting(case.controller.Kc, case.controller.Ti_s)
    ratio = (
        predict(truth, setting, case.ts, params).iae / predict(truth, present, case.ts, params).iae
    )
    tally.made += 1
    tally.robust += robustness(truth, setting, case.ts).gain_margin >= 1.7
    tally.better += ratio <= 0.7
    tally.small += abs(ratio - 1.0) < 0.2


def proposals(n: int, seed: int, loads: float, per_window: list[float]) -> list[float]:
    print(f"2. proposals (loads x{loads:g}, set-point steps)")
    cost: list[float] = []
    for tuning in ("aggressive", "sluggish", "good"):
        tallies: dict[str, _Tally] = {}
        averaging = _Tally()
        for i in range(n):
            case = tuning_case(seed + 10_000 + i, tuning, loads)  # type: ignore[arg-type]
            r = case.record
            # the chain identifies the present controller anyway (its stick-slip step):
            # the retuning adds what ``tuning_for`` costs
            pi = identify_pi(r.op, r.pv, r.sp, case.ts)
            cause = f"{'sluggish' if tuning == 'good' else tuning}_tuning"
            settings = TuningSettings(retune=RetuneParams(level_control=case.level_control))
            t0 = time.perf_counter()
            out = tuning_for(
                cause, r.pv, r.op, case.ts, case.loop_type, case.sp_steps, None, pi, settings
            )
            took_ms = (time.perf_counter() - t0) * 1e3
            cost.append(took_ms * 3600 / r.pv.size)
            per_window.append(took_ms)
            assert out is not None
            tally = tallies.setdefault(case.loop_type, _Tally())
            tally.loops += 1
            if out.json["proposed"] is not None:
                _judge(case, out.json["proposed"], tally)
            if case.loop_type == "level":
                # the same level loop had it been configured for averaging control
                averaging.loops += 1
                loose = tuning_for(
                    cause, r.pv, r.op, case.ts, case.loop_type, case.sp_steps, None, pi
                )
                if loose is not None and loose.json["proposed"] is not None:
                    _judge(case, loose.json["proposed"], averaging)
        _report(tuning, tallies, averaging)
    return cost


def _report(tuning: str, tallies: dict[str, _Tally], averaging: _Tally) -> None:
    total = _Tally(*(sum(getattr(t, f.name) for t in tallies.values()) for f in fields(_Tally)))
    rows = [("all", total), *sorted(tallies.items()), ("level if averaging", averaging)]
    for family, t in rows:
        if tuning == "good":
            print(
                f"   good       {family:18s}: {t.loops - t.made}/{t.loops} no proposal, "
                f"{t.small} with the error integral within 20 %: "
                f"{t.loops - t.made + t.small}/{t.loops} as asked"
            )
        else:
            print(
                f"   {tuning:10s} {family:18s}: proposal for {t.made}/{t.loops}; gain margin "
                f">= 1.7 in {t.robust}/{t.made}; error integral <= 0.7x in {t.better}/{t.made}"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=60, help="loops per figure")
    ap.add_argument("--seed", type=int, default=5000, help="first seed")
    a = ap.parse_args()
    identification(a.cases, a.seed)
    per_window: list[float] = []
    cost = proposals(a.cases, a.seed, 0.3, per_window)
    print(
        f"3. identification + proposal: median {np.median(cost):.1f} ms, 95th percentile "
        f"{np.percentile(cost, 95):.1f} ms per 3,600 samples; per window (1,500-3,600 "
        f"samples, much of the cost fixed) median {np.median(per_window):.1f} ms, 95th "
        f"percentile {np.percentile(per_window, 95):.1f} ms"
    )


if __name__ == "__main__":
    main()
