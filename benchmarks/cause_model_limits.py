"""What limits the learned cause decision: more fit windows, or larger trees (issue 46)?

Fits LightGBM on the first 16,000, 32,000 and 64,000 windows of the fit seed, then on all of
them with deeper trees (63 leaves, 7 levels, half the learning rate, twice the rounds), and
prints each one's macro-F1 and per-class F1 on the calibration seed's windows, and where the
fit with the shipped settings errs (true cause against the one given, accuracy per family and
under 300 samples, as ``cause_model_accuracy.py`` prints it). The check seed stays for
``cause_model_accuracy.py``'s figures, and real records play no part. When doubling the
windows or the trees gains little, the evidence the chain gathers is what limits the decision
(Ke et al. 2017 for the trees).

    python benchmarks/cause_model_limits.py [--cache build/corpus] [--identification 1200]

``--identification N`` draws the calibration seed's first N windows again and reads, against
the corpus' true process and controller, the evidence's identified controller over its SIMC
setting (``evidence.process_evidence``; Skogestad 2003 with τc = θ): the input an oracle given
the true ratio lifted from 0.855 to 0.943 (benchmarks/README.md, evidence version 7).

The evidence comes from the cache ``plantcheck model fit --cache`` fills (drawn when absent:
about an hour on two cores).
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
import argparse
import math
import multiprocessing
import time
from collections import Counter
from pathlib import Path

from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as `model fit` does: the evidence drawn depends on it

import numpy as np
from cause_model_accuracy import accuracy_per_family
from numpy.typing import NDArray

from plantcheck.diagnosis.chain import chain_evidence
from plantcheck.service.cause_model_fit import (
    CALIBRATION_SEED,
    FIT_SEED,
    FIT_WINDOWS,
    ROUNDS,
    CorpusEvidence,
    corpus_evidence,
    fit_trees,
    macro_f1,
    side_windows,
)
from plantcheck.simulator.cases import simc_pi_tc
from plantcheck.simulator.corpus import CLASSES, draw_case

DEEPER = {"num_leaves": 63, "max_depth": 7, "min_data_in_leaf": 40, "learning_rate": 0.05}


def errors(cal: CorpusEvidence, pred: NDArray[np.int64]) -> None:
    """Each true cause's verdicts, then the share right per family value and window length."""
    for c, name in enumerate(CLASSES):
        given = Counter(CLASSES[k] for k in pred[cal.y == c])
        print(f"  {name}: {dict(given.most_common())}")
    accuracy_per_family(cal, pred)


def _ratios(index: int) -> tuple[str, float, float, float, float, float, str] | None:
    """One window's (set-point family, identified and true log10 Kc/Kc_SIMC, identified and
    true log10 Ti/Ti_SIMC, the quick process fit, the true cause); None where the evidence
    has no ratio."""
    case, rec = draw_case(CALIBRATION_SEED, index)
    cfg = case.config
    _, ev = chain_evidence(rec.pv, rec.op, cfg.sample_time_s, sp=rec.sp, loop_type=case.loop_type)
    if ev is None or ev.get("kc_over_simc") is None or ev.get("ti_over_simc") is None:
        return None
    simc = simc_pi_tc(cfg.process, 1.0)
    true_kc = math.log10(abs(cfg.controller.Kc / simc.Kc))
    true_ti = math.log10(cfg.controller.Ti_s / simc.Ti_s)
    found = [float(ev[k] or 0.0) for k in ("kc_over_simc", "ti_over_simc", "process_fit")]
    return case.family["sp"], found[0], true_kc, found[1], true_ti, found[2], case.cause


def identification(n: int) -> None:
    """How closely the identified controller-over-SIMC ratios follow the true ones."""
    with multiprocessing.get_context("fork").Pool() as pool:
        rows = [r for r in pool.map(_ratios, range(n), chunksize=8) if r is not None]
    a = np.array([r[1:6] for r in rows])
    err = np.abs(a[:, 0] - a[:, 1])
    print(f"identified against true ratio, {len(rows)} of {n} windows with both ratios:")
    print(
        f"  Kc/Kc_SIMC: correlation {np.corrcoef(a[:, 0], a[:, 1])[0, 1]:.2f}, "
        f"median |error| {np.median(err):.2f} decades, over 0.3 decades in {np.mean(err > 0.3):.2f}"
    )
    print(f"  Ti/Ti_SIMC: correlation {np.corrcoef(a[:, 2], a[:, 3])[0, 1]:.2f}, "
          f"median |error| {np.median(np.abs(a[:, 2] - a[:, 3])):.2f} decades")  # fmt: skip
    for what, col in (("set point", 0), ("true cause", 6)):
        values = np.array([r[col] for r in rows])
        for v in sorted(set(values)):
            e = err[values == v]
            print(f"  {what} {v}: {e.size} windows, Kc median |error| {np.median(e):.2f}")
    for lo, hi in ((-np.inf, 0.3), (0.3, 0.6), (0.6, 0.9), (0.9, np.inf)):
        e = err[(a[:, 4] >= lo) & (a[:, 4] < hi)]
        if e.size:
            print(f"  process fit {lo:g} to {hi:g}: {e.size} windows, "
                  f"Kc median |error| {np.median(e):.2f}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", type=Path, default=Path("build/corpus"))
    ap.add_argument("--identification", type=int, default=0, metavar="N")
    args = ap.parse_args()
    if args.identification:
        identification(args.identification)
        return
    fit = corpus_evidence(FIT_SEED, FIT_WINDOWS, cache=args.cache, progress=print)
    cal = corpus_evidence(CALIBRATION_SEED, side_windows(FIT_WINDOWS), cache=args.cache)
    print(f"macro-F1 on the calibration seed ({cal.y.size} windows); per class {CLASSES}")
    runs: list[tuple[str, int, dict[str, float] | None, int]] = [
        (f"{n} windows", n, None, ROUNDS) for n in (16_000, 32_000, fit.y.size)
    ]
    runs.append((f"{fit.y.size} windows, deeper trees", fit.y.size, DEEPER, 2 * ROUNDS))
    for label, n, changed, rounds in runs:
        t0 = time.monotonic()
        booster = fit_trees(fit.x[:n], fit.y[:n], changed=changed, rounds=rounds)
        pred = booster.predict(cal.x, raw_score=True).argmax(axis=1)
        f1, per = macro_f1(cal.y, pred, len(CLASSES))
        shown = " ".join(f"{v:.2f}" for v in per)
        print(f"{label:>32}: {f1:.3f}  ({shown})  fitted in {time.monotonic() - t0:.0f} s")
        if n == fit.y.size and changed is None:
            errors(cal, pred)


if __name__ == "__main__":
    main()
