"""False alarms under slow periodic loads: healthy loops whose load swings 1.5-6 times in the
two-hour window (issue 24's "no new false alarms").

A disturbance from upstream that cycles every 20-80 minutes turns OP only a few times in a
two-hour window, so each of its ramps is a large share of OP's travel, as a sticky valve's
are, and the PV's return toward the set point after each turn can look like a slip. The
grid: slow pressure-like loops at 10 s (τ 60 or 200 s, dead time 20 s, K 1.5) with a PI of
gain 0.4 or 1.2, a sinusoidal load of period 1,200, 2,400 or 4,800 s and amplitude 1 or 3 %
of travel on top of a slow random walk, noise σ 0.05, 0.2 or 0.5 % of span, with and without
a set-point step, two seeds: 288 windows of 720 samples, all healthy. Prints how many read
``stiction``, per period and noise level, and the causes given.

    python benchmarks/slow_load_false_alarms.py [-v] [--decision rules|learned] [--model FILE]

``--decision learned``: the learned decision names the cause, ``--model FILE`` another model
file than the shipped one.
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections
import itertools
import time

from model_option import add_decision_options, decision_params

from plantcheck.diagnosis import diagnose
from plantcheck.simulator.loop import (
    Disturbance,
    LoopConfig,
    PIController,
    Process,
    simulate_loop,
)

PERIODS_S = (1200.0, 2400.0, 4800.0)
AMPLITUDES = (1.0, 3.0)
NOISES = (0.05, 0.2, 0.5)
GAINS = (0.4, 1.2)
LAGS_S = (60.0, 200.0)
SEEDS = (7, 8)


def window(
    period: float, amp: float, noise: float, kc: float, tau: float, seed: int, step: bool
) -> LoopConfig:
    """One healthy two-hour window at 10 s under a slow sinusoidal load."""
    return LoopConfig(
        process=Process("fopdt", K=1.5, tau_s=tau, theta_s=20.0),
        controller=PIController(Kc=kc, Ti_s=max(tau, 120.0)),
        sample_time_s=10.0,
        n_samples=720,
        warmup_samples=200,
        noise_std=noise,
        sp_steps=((2500.0, 53.0),) if step else (),
        disturbances=(
            Disturbance(sine_amplitude=amp, sine_period_s=period, random_walk_std=0.003),
        ),
        seed=seed,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("-v", "--verbose", action="store_true", help="list every false alarm")
    add_decision_options(ap)
    args = ap.parse_args()
    params = decision_params(args)
    t0 = time.perf_counter()
    alarms: collections.Counter[tuple[float, float]] = collections.Counter()
    windows: collections.Counter[tuple[float, float]] = collections.Counter()
    causes: collections.Counter[str] = collections.Counter()
    grid = itertools.product(PERIODS_S, AMPLITUDES, NOISES, GAINS, LAGS_S, SEEDS, (False, True))
    for period, amp, noise, kc, tau, seed, step in grid:
        r = simulate_loop(window(period, amp, noise, kc, tau, seed, step))
        d = diagnose(r.pv, r.op, 10.0, sp=r.sp, loop_type="pressure", quantify=False,
                     params=params)  # fmt: skip
        causes[d.cause] += 1
        windows[(period, noise)] += 1
        if d.cause == "stiction":
            alarms[(period, noise)] += 1
            if args.verbose:
                print(
                    f"  period {period:.0f} s, amplitude {amp} %, noise {noise} %, Kc {kc}, "
                    f"tau {tau:.0f} s, seed {seed}, step {step}"
                )
    print(
        f"healthy loops under slow periodic loads: {sum(windows.values())} windows, "
        f"{time.perf_counter() - t0:.0f} s, decision {args.decision}"
    )
    print(f"{'period s':>9s} " + " ".join(f"{'noise ' + str(n):>11s}" for n in NOISES))
    for period in PERIODS_S:
        cells = " ".join(f"{alarms[(period, n)]:5d}/{windows[(period, n)]:<5d}" for n in NOISES)
        print(f"{period:9.0f} {cells}")
    total = sum(alarms.values())
    print(
        f"read stiction: {total} of {sum(windows.values())} ({total / sum(windows.values()):.1%})"
    )
    print("causes: " + ", ".join(f"{c} {k}" for c, k in causes.most_common()))


if __name__ == "__main__":
    main()
