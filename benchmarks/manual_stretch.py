"""Healthy loops with a stretch in manual or a transmitter frozen for a while (issue 46 items 1
and 7), diagnosed with and without the mode flag.

Many plants map no auto/manual tag. An operator who takes a loop in manual holds OP still while
the loads move the PV; a diagnosis that does not know it reads a loop whose OP stood still on a
moving error, which no PI law does. A transmitter that freezes shows the controller a constant
error: OP ramps on a straight line while the recorded PV stands still, then the PV jumps to
where the process went, which reads like a sticky valve's stuck phase and slip. The grid:
self-regulating loops (FOPDT, lag-dominant or balanced), SIMC-tuned, under coloured loads,
3,600 samples at 1 s, three noise levels, put in manual (``ClosedLoop.auto`` False: OP held,
bumpless return) or with the transmitter frozen (``ClosedLoop.frozen_pv``) for 0, 3, 10 or 30 %
of the window in its middle, ``--seeds`` draws of each cell: every window is healthy. Prints,
per share, the causes read without the mode flag and with it (``auto``: the chain leaves manual
samples out, and a window below ``WindowParams.min_auto_fraction`` in automatic reads
``manual_mode``), and with the transmitter frozen.

Fifty-first session: without the flag the rules read 7 of the 24 windows 10 % in manual as
sticky valves, the learned decision 12; with it, 10 % and 30 % read ``manual_mode``.
Fifty-second session: the window checks read an OP held bit for bit under a live PV, away from
its extremes and not to the window's end, as manual samples (``window.held_output``), a PV held
bit for bit while OP ramps without its noise as a frozen transmitter (``window.frozen_pv``),
and the stick-slip search counts no event across the samples the checks filled in. The rules
now read 10 % and 30 % in manual as ``manual_mode`` with the flag or without, frozen as
``data_quality`` (the code before: 21 and 13 of 24 as sticky valves), and 3 % (bridged) as the
same loops never in manual read (0 %: stiction 7 of 24, the rules' own false alarms on the
balanced process; 3 % in manual 7, was 7 unflagged and 10 flagged; 3 % frozen 7, was 13).
A window 5-10 % in manual is then judged on its longest automatic stretch (methods §1 judges a
window 90 % in automatic): 10 % in manual reads as the loops never in manual (seeds 4-11:
ok 36-37, stiction 11 against the reference's ok 35, stiction 11), 30 % ``manual_mode``.

``--decision learned``: the learned decision names the cause, ``--model FILE`` another model
file than the shipped one. The corpus the decision is fitted on draws no manual stretch (the
fifty-first session's note in benchmarks/README.md).

    python benchmarks/manual_stretch.py [--seeds 4] [--first-seed 0] [--decision rules|learned]
        [--model FILE]
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections
import itertools
import time

import numpy as np
from model_option import add_decision_options, decision_params

from plantcheck.diagnosis import diagnose
from plantcheck.simulator.cases import simc_pi
from plantcheck.simulator.loop import (
    ClosedLoop,
    Disturbance,
    LoopConfig,
    LoopRecord,
    Process,
    loop_inputs,
    loop_record,
)

PROCESSES = (
    Process("fopdt", K=1.0, tau_s=40.0, theta_s=4.0),
    Process("fopdt", K=1.5, tau_s=15.0, theta_s=8.0),
)
"""A lag-dominant and a balanced process (s)."""
NOISES = (0.05, 0.2, 0.5)
"""PV noise σ, % of span."""
SHARES = (0.0, 0.03, 0.1, 0.3)
"""The share of the window in manual or frozen, centred in it (0: the same loops never in
manual, the reference: what the diagnosis reads on them without any such stretch)."""
SAMPLES = 3600


def stretch_window(
    proc: Process, noise: float, share: float, seed: int, frozen: bool = False
) -> tuple[LoopRecord, np.ndarray]:
    """One healthy window with the middle ``share`` of it in manual (or, ``frozen``, with the
    transmitter frozen there: the controller, in automatic, and the record see the PV's last
    value), and its mode flag (True in automatic)."""
    cfg = LoopConfig(
        process=proc,
        controller=simc_pi(proc),
        noise_std=noise,
        n_samples=SAMPLES,
        disturbances=(Disturbance(filtered_noise_std=1.0, filtered_noise_tau_s=5 * proc.tau_s),),
        seed=seed,
    )
    rng, t, sp, load, out_d, meas = loop_inputs(cfg)
    loop = ClosedLoop(cfg)
    w = cfg.warmup_samples
    a = w + int((0.5 - share / 2) * SAMPLES)
    b = w + int((0.5 + share / 2) * SAMPLES)
    runs: list[tuple[list[float], list[float], list[float]]] = []
    for lo, hi, live in ((0, a, True), (a, b, False), (b, t.size, True)):
        loop.auto = live or frozen
        loop.frozen_pv = None if live or not frozen or not runs else runs[-1][0][-1]
        runs.append(loop.run(sp[lo:hi].tolist(), load[lo:hi].tolist(), out_d[lo:hi].tolist(),
                             meas[lo:hi].tolist()))  # fmt: skip
    pv, op, mv = (
        np.concatenate([np.asarray(r[i], dtype=np.float64) for r in runs]) for i in range(3)
    )
    mode = np.ones(SAMPLES, dtype=bool)
    if not frozen:
        mode[a - w : b - w] = False
    return loop_record(cfg, rng, t, sp, pv, op, mv), mode


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=4, help="draws of each cell (default 4)")
    ap.add_argument("--first-seed", type=int, default=0, help="the first draw's seed (default 0)")
    add_decision_options(ap)
    args = ap.parse_args()
    if args.seeds < 1:
        ap.error(f"--seeds {args.seeds}: give at least 1")
    if args.first_seed < 0:
        ap.error(f"--first-seed {args.first_seed}: give 0 or more")
    params = decision_params(args)
    t0 = time.perf_counter()
    read: dict[tuple[float, str], collections.Counter[str]] = collections.defaultdict(
        collections.Counter
    )
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    grid = itertools.product(PROCESSES, NOISES, SHARES, seeds)
    for proc, noise, share, seed in grid:
        for frozen in (False, True):
            rec, mode = stretch_window(proc, noise, share, seed, frozen)
            for flagged in (False, True) if not frozen else (False,):
                d = diagnose(rec.pv, rec.op, 1.0, sp=rec.sp, auto=mode if flagged else None,
                             loop_type="temperature", quantify=False, params=params)  # fmt: skip
                how = "frozen" if frozen else "flagged" if flagged else "manual"
                read[(share, how)][d.cause] += 1
    windows = len(PROCESSES) * len(NOISES) * args.seeds
    print(f"healthy loops with a manual stretch or a frozen transmitter: {windows} windows "
          f"per share, decision {args.decision}, {time.perf_counter() - t0:.0f} s")  # fmt: skip
    rows = {
        "manual": "in manual, without the mode flag",
        "flagged": "in manual, with the mode flag   ",
        "frozen": "with the transmitter frozen     ",
    }
    for share, how in itertools.product(SHARES, rows):
        causes = ", ".join(f"{c} {k}" for c, k in read[(share, how)].most_common())
        print(f"{100 * share:3.0f} % {rows[how]}: {causes}")


if __name__ == "__main__":
    main()
