"""What limits the learned cause decision: more fit windows, or larger trees (issue 46)?

Fits LightGBM on the first 16,000, 32,000 and 64,000 windows of the fit seed, then on all of
them with deeper trees (63 leaves, 7 levels, half the learning rate, twice the rounds), and
prints each one's macro-F1 and per-class F1 on the calibration seed's windows, and where the
fit with the shipped settings errs (true cause against the one given, accuracy per family and
per window length). The check seed
stays for ``cause_model_accuracy.py``'s figures, and real records play no part. When doubling
the windows or the trees gains little, the evidence the chain gathers is what limits the
decision (Ke et al. 2017 for the trees).

    python benchmarks/cause_model_limits.py [--cache build/corpus]

The evidence comes from the cache ``plantcheck model fit --cache`` fills (drawn when absent:
about an hour on two cores).
"""

from __future__ import annotations

import argparse
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

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
from plantcheck.simulator.corpus import CLASSES, FAMILY_KEYS

DEEPER = {"num_leaves": 63, "max_depth": 7, "min_data_in_leaf": 40, "learning_rate": 0.05}


LENGTHS = (300, 1_000, 3_000)
"""Window-length bins (samples) of the error breakdown."""


def errors(cal: CorpusEvidence, pred: NDArray[np.int64]) -> None:
    """Each true cause's verdicts, then the share right per family value and per length."""
    for c, name in enumerate(CLASSES):
        given = Counter(CLASSES[k] for k in pred[cal.y == c])
        print(f"  {name}: {dict(given.most_common())}")
    right = pred == cal.y
    for key in FAMILY_KEYS:
        by: defaultdict[str, list[bool]] = defaultdict(list)
        for value, ok in zip(cal.family[key], right, strict=True):
            by[value].append(bool(ok))
        print(
            f"  {key}: "
            + ", ".join(f"{v} {np.mean(b):.2f}/{len(b)}" for v, b in sorted(by.items()))
        )
    bins = np.digitize(cal.samples, LENGTHS)
    edges = ("<300", "300-1000", "1000-3000", ">=3000")
    print("  samples: " + ", ".join(
        f"{e} {right[bins == i].mean():.2f}/{(bins == i).sum()}" for i, e in enumerate(edges)
    ))  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", type=Path, default=Path("build/corpus"))
    args = ap.parse_args()
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
