"""The learned cause decision on simulated windows it never saw (issue 46).

Prints, on the check seed's windows: macro-F1 and per-class F1 of the shipped model and of the
rules on the same windows, the expected calibration error with the reliability table (and a
PNG when matplotlib is present), accuracy per family; then, with ``--left-out``, the families
left out one at a time: a model fitted without a family's windows, tested on that family's
check windows, beside the full model on the same windows.

    python benchmarks/cause_model_accuracy.py [--windows 64000] [--left-out] [--png FILE]
        [--check-seed 404] [--strength] [--model FILE]

``--model FILE``: read another model file than the shipped one (``plantcheck model fit --out
FILE``, say with ``--tree-seed`` or ``--shape-seed``: how far one fit's figures are a draw).
The trees' and the shape network's figures alone are printed beside the blend's.

``--against FILE``: also read the model in FILE (``shipped`` for the shipped one) on the same
windows and print the macro-F1 difference with its paired bootstrap standard error (500
resamples) and how many windows the two read differently: whether a refit differs from the
file it would replace by more than chance.

``--check-seed``: read another seed's windows than the fit's check seed (303, which many
choices have read): 404 was drawn in the thirty-second session and read by no choice before.

``--strength``: how strongly each fault shows, against the decision's accuracy: every fault
window of the check seed is simulated again with its twin (the same loop without the fault)
and read by the ratio the corpus keeps it by (``corpus.fault_and_twin``: the error's σ over
the twin's, or the square root of the ringing power's ratio), per band of that ratio and,
for the classes a detuned controller may carry, per tuning (about 5 minutes on two cores).

The corpus' evidence is kept in build/corpus (the same cache ``plantcheck model fit --cache``
fills), so a second run only fits.
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
import argparse
import math
import multiprocessing
import sys
from dataclasses import replace
from pathlib import Path

from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as `model fit` does: the evidence drawn depends on it

import numpy as np
from model_option import chosen_model
from numpy.typing import NDArray

from plantcheck.service.cause_model_fit import (
    CALIBRATION_SEED,
    CHECK_SEED,
    FIT_SEED,
    FIT_WINDOWS,
    SHAPE_WINDOW_FACTOR,
    TREE_WINDOW_FACTOR,
    CorpusEvidence,
    corpus_evidence,
    corpus_evidence_and_shapes,
    expected_calibration_error,
    export_trees,
    fit_temperature,
    fit_trees,
    macro_f1,
    model_probabilities,
    paired_macro_f1_difference,
    raw_scores,
    reliability,
    shape_log_probabilities_of,
    side_windows,
    with_blend,
    with_networks,
)
from plantcheck.service.shape_model_fit import CorpusShapes, corpus_shapes
from plantcheck.simulator.corpus import CLASSES, FAMILIES, draw_case, fault_and_twin

CACHE = Path(__file__).resolve().parents[1] / "build" / "corpus"

LEFT_OUT: tuple[tuple[str, str], ...] = (
    ("valve", "kano"),
    ("valve", "he"),
    ("valve", "choudhury"),
    ("valve", "backlash"),
    ("process", "integrating"),
    ("process", "inverse"),
    ("process", "deadtime"),
    ("recording", "compressed"),
    ("recording", "quantised"),
    ("limit", "anywhere"),
    ("sp", "cascade"),
    ("tuning", "detuned"),
    ("load", "random_walk"),
    ("operation", "manual"),
)
"""The families left out one at a time (issue 46 item 6)."""


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def plot(table: list[tuple[float, float, int]], path: Path, ece: float) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        say("matplotlib not installed: no PNG (pip install matplotlib)")
        return
    fig, ax = plt.subplots(figsize=(4.5, 4.5), dpi=100)
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="perfect calibration")
    ax.plot([c for c, _, _ in table], [a for _, a, _ in table], "o-", label="learned decision")
    for c, a, n in table:
        ax.annotate(str(n), (c, a), textcoords="offset points", xytext=(4, -10), fontsize=7)
    ax.set_xlabel("probability of the cause given")
    ax.set_ylabel("share of windows where it was the true cause")
    ax.set_title(f"Reliability on simulated check windows (ECE {ece:.3f})", fontsize=9)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    say(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=FIT_WINDOWS)
    ap.add_argument("--left-out", action="store_true")
    ap.add_argument(
        "--only",
        action="append",
        metavar="KEY=VALUE",
        help="leave out only these families (repeatable; default: all of LEFT_OUT)",
    )
    ap.add_argument(
        "--png",
        type=Path,
        default=None,
        help="the reliability plot (default: benchmarks/reliability.png for the check seed, "
        "none for another)",
    )
    ap.add_argument("--check-seed", type=int, default=CHECK_SEED, metavar="SEED",
                    help=f"the seed whose windows are read (default {CHECK_SEED})")  # fmt: skip
    ap.add_argument("--strength", action="store_true",
                    help="accuracy per band of how strongly each fault shows (5 min)")  # fmt: skip
    ap.add_argument("--model", type=Path, default=None,
                    help="model file to read (default: the shipped one)")  # fmt: skip
    ap.add_argument("--against", default=None, metavar="FILE",
                    help="compare with this model file ('shipped': the shipped one) on the same "
                    "windows: the macro-F1 difference and its paired standard error")  # fmt: skip
    a = ap.parse_args()
    if a.check_seed in (FIT_SEED, CALIBRATION_SEED):
        sys.exit(f"--check-seed {a.check_seed}: the model was fitted or calibrated on it")
    png = a.png
    if png is None and a.check_seed == CHECK_SEED and a.model is None:
        png = Path(__file__).with_name("reliability.png")
    names = {f"{k}={v}": (k, v) for k, v in LEFT_OUT}
    unknown = [o for o in a.only or [] if o not in names]
    if unknown:  # before the check figures: a typo costs no wait
        sys.exit(f"--only {unknown[0]}: not one of LEFT_OUT ({', '.join(names)})")
    families = tuple(names[o] for o in a.only or []) or LEFT_OUT
    model = chosen_model(a.model)
    if model is None:
        sys.exit("no shipped model: run plantcheck model fit first")
    other = None
    if a.against is not None:
        other = chosen_model(None if a.against == "shipped" else Path(a.against), "--against")
        if other is None:
            sys.exit("--against shipped: no shipped model (run plantcheck model fit first)")
    small = side_windows(a.windows)
    chk_shapes = None
    if model.shape is not None or (other is not None and other.shape is not None):
        chk, chk_shapes = corpus_evidence_and_shapes(a.check_seed, small, progress=say,
                                                     cache=CACHE)  # fmt: skip
    else:
        chk = corpus_evidence(a.check_seed, small, progress=say, cache=CACHE)
    p = model_probabilities(model, chk, chk_shapes)
    pred = p.argmax(axis=1)
    mf1, f1s = macro_f1(chk.y, pred, len(CLASSES))
    rules = np.array([CLASSES.index(r) if r in CLASSES else -1 for r in chk.rules])
    rf1, rf1s = macro_f1(chk.y, rules, len(CLASSES))
    ece = expected_calibration_error(p, chk.y)
    print(f"check seed {a.check_seed}: {chk.y.size} windows ({chk.skipped} with nothing to weigh)")
    print(f"learned macro-F1 {mf1:.3f}, accuracy {np.mean(pred == chk.y):.3f}; "
          f"rules macro-F1 {rf1:.3f}, accuracy {np.mean(rules == chk.y):.3f}")  # fmt: skip
    trees = raw_scores(model, chk.x).argmax(axis=1)
    alone = [f"trees alone {macro_f1(chk.y, trees, len(CLASSES))[0]:.3f}"]
    if chk_shapes is not None:
        net = shape_log_probabilities_of(model, chk_shapes).argmax(axis=1)
        alone.append(f"shape network alone {macro_f1(chk.y, net, len(CLASSES))[0]:.3f}")
    print("; ".join(alone))
    if other is not None:
        pred_other = model_probabilities(other, chk, chk_shapes).argmax(axis=1)
        diff, se = paired_macro_f1_difference(chk.y, pred, pred_other, len(CLASSES))
        print(f"against {a.against}: macro-F1 {macro_f1(chk.y, pred_other, len(CLASSES))[0]:.4f}; "
              f"this file less it {diff:+.4f}, paired bootstrap standard error {se:.4f} "
              f"(500 resamples of the same windows); {int(np.sum(pred != pred_other))} of "
              f"{chk.y.size} windows read differently")  # fmt: skip
    print("class".ljust(22) + "learned F1   rules F1")
    for cls, f, r in zip(CLASSES, f1s, rf1s, strict=True):
        print(f"{cls:22s}{f:10.3f}{r:11.3f}")
    table = reliability(p, chk.y)
    print(f"expected calibration error {ece:.3f}; reliability (confidence, accuracy, windows):")
    for c, acc, n in table:
        print(f"  {c:.2f}  {acc:.2f}  {n}")
    if png is not None:
        plot(table, png, ece)
    print("accuracy per family (learned / rules, windows):")
    accuracy_per_family(chk, pred, rules)
    if a.strength:
        if chk_shapes is None:
            say(
                "--strength: the model has no shape network, whose inputs say which windows "
                "were judged: no table"
            )
        else:
            strength(a.check_seed, np.flatnonzero(chk_shapes.judged), chk, pred)
    if a.left_out:
        left_out(a.windows, chk, chk_shapes, pred, families, 1 + len(model.shape_more))


def accuracy_per_family(
    ev: CorpusEvidence, pred: NDArray[np.int64], rules: NDArray[np.int64] | None = None
) -> None:
    """Print the share of ``ev``'s windows ``pred`` gets right per family value (and the
    rules' share beside it when given), then per band of the window's length
    (``LENGTH_BANDS``)."""
    right = pred == ev.y
    for key, values in FAMILIES.items():
        fam = np.array(ev.family[key])
        cells = []
        for v in values:
            m = fam == v
            if m.any():
                beside = "" if rules is None else f"/{np.mean(rules[m] == ev.y[m]):.2f}"
                cells.append(f"{v} {np.mean(right[m]):.2f}{beside} ({int(m.sum())})")
        print(f"  {key}: " + ", ".join(cells))
    cells = []
    for lo, hi in zip(LENGTH_BANDS, (*LENGTH_BANDS[1:], math.inf), strict=True):
        m = (ev.samples >= lo) & (ev.samples < hi)
        if m.any():
            span = f"{lo:,}+" if hi == math.inf else f"{lo:,}-{hi:,}"
            cells.append(f"{span} {np.mean(right[m]):.2f} ({int(m.sum())})")
    print("  window samples: " + ", ".join(cells))


LENGTH_BANDS = (0, 300, 1_000, 3_000)
"""Lower ends of the window-length bands (samples) the accuracy is read per: short windows
hold fewer cycles and responses, and the decision is less sure of them."""


STRENGTH_BANDS = (1.3, 1.5, 2.0, 3.0, 5.0, math.inf)
"""Bands of the fault-over-twin ratio; ``corpus.VISIBLY_FAULTY`` (1.3) keeps a window."""


def _fault_ratio(seed_index: tuple[int, int]) -> float:
    """The window's fault-over-twin ratio (NaN without a twin), the ringing power's
    square-rooted so that every class reads in units of the error's σ."""
    case, rec = draw_case(*seed_index)
    shown = fault_and_twin(case, rec)
    if shown is None:
        return math.nan
    ratio = shown[0] / max(shown[1], 1e-300)
    return math.sqrt(ratio) if case.cause == "aggressive_tuning" else ratio


def strength(
    seed: int, index: NDArray[np.int64], ev: CorpusEvidence, pred: NDArray[np.int64]
) -> None:
    """Print the accuracy of ``pred`` per class and band of the fault-over-twin ratio, and per
    tuning for the classes drawn with a detuned controller in half their windows."""
    faulty = np.array([CLASSES[c] not in ("ok", "saturation") for c in ev.y])
    ratio = np.full(ev.y.size, math.nan)
    with multiprocessing.get_context("fork").Pool() as pool:
        ratio[faulty] = pool.map(_fault_ratio, [(seed, int(i)) for i in index[faulty]], 16)
    tuning = np.array(ev.family["tuning"])
    print(
        "accuracy per band of the fault's error over its twin's (ringing power's ratio, "
        "square-rooted, for aggressive tuning):"
    )
    for c, name in enumerate(CLASSES):
        of = faulty & (ev.y == c)
        if not of.any():
            continue
        cells = []
        for lo, hi in zip((0.0, *STRENGTH_BANDS[:-1]), STRENGTH_BANDS, strict=True):
            m = of & (ratio >= lo) & (ratio < hi)
            if m.any():
                miss = np.bincount(pred[m][pred[m] != c], minlength=len(CLASSES))
                worst = f", {CLASSES[int(miss.argmax())]} {int(miss.max())}" if miss.any() else ""
                cells.append(f"{lo:g}-{hi:g} {np.mean(pred[m] == c):.2f} ({int(m.sum())}{worst})")
        print(f"  {name}: " + "; ".join(cells))
        by_tuning = [f"{t} {np.mean(pred[of & (tuning == t)] == c):.2f} "
                     f"({int(np.sum(of & (tuning == t)))})"
                     for t in FAMILIES["tuning"] if np.any(of & (tuning == t))]  # fmt: skip
        if len(by_tuning) > 1:
            print(f"    per tuning: {', '.join(by_tuning)}")


def left_out(
    windows: int,
    chk: CorpusEvidence,
    chk_shapes: CorpusShapes | None,
    pred: np.ndarray,
    families: tuple[tuple[str, str], ...] = LEFT_OUT,
    networks: int = 1,
) -> None:
    """Fit without each of ``families``, test on its check windows, as ``plantcheck model
    fit`` does: the trees on ``TREE_WINDOW_FACTOR`` times ``windows``, and ``networks`` shape
    networks (on the judged windows of the other families among their ``SHAPE_WINDOW_FACTOR``
    times as many) averaged and blended in as the shipped model's are, when it has them."""
    small = side_windows(windows)
    wide = SHAPE_WINDOW_FACTOR * windows
    shapes = None
    if chk_shapes is not None and wide == TREE_WINDOW_FACTOR * windows:
        # the networks read the trees' windows: each simulated once for both
        fit, fit_shapes = corpus_evidence_and_shapes(FIT_SEED, wide, progress=say, cache=CACHE)
        cal, cal_shapes = corpus_evidence_and_shapes(CALIBRATION_SEED, small, progress=say,
                                                     cache=CACHE)  # fmt: skip
        shapes = (fit_shapes, cal_shapes, fit.family)
    else:
        fit = corpus_evidence(FIT_SEED, TREE_WINDOW_FACTOR * windows, progress=say, cache=CACHE)
        cal = corpus_evidence(CALIBRATION_SEED, small, progress=say, cache=CACHE)
        if chk_shapes is not None:
            # the networks read another number of windows: their families come with their
            # evidence
            wide_family = corpus_evidence(FIT_SEED, wide, progress=say, cache=CACHE).family
            shapes = (corpus_shapes(FIT_SEED, wide, progress=say, cache=CACHE),
                      corpus_shapes(CALIBRATION_SEED, small, progress=say, cache=CACHE),
                      wide_family)  # fmt: skip
    print("left-out family          windows  full model  fitted without  drop   (accuracy)")
    for key, value in families:
        keep = np.array(fit.family[key]) != value
        booster = fit_trees(fit.x[keep], fit.y[keep])
        cal_keep = np.array(cal.family[key]) != value
        m = export_trees(booster, 1.0, {})
        m = replace(m, temperature=fit_temperature(raw_scores(m, cal.x[cal_keep]), cal.y[cal_keep]))
        fam = np.array(chk.family[key]) == value
        chk_fam = _rows(chk, fam)
        fam_shapes = None
        if shapes is not None and chk_shapes is not None:
            fit_shapes, cal_shapes, net_family = shapes
            net_keep = np.array(net_family[key]) != value
            net_windows = _judged_rows(fit_shapes, net_keep)
            m = with_blend(with_networks(m, net_windows, networks, progress=say),
                           _rows(cal, cal_keep), _judged_rows(cal_shapes, cal_keep),
                           net_windows.y.size)  # fmt: skip
            fam_shapes = _judged_rows(chk_shapes, fam)
        y = chk.y[fam]
        p_out = model_probabilities(m, chk_fam, fam_shapes).argmax(axis=1)
        full, out = float(np.mean(pred[fam] == y)), float(np.mean(p_out == y))
        print(
            f"{key + '=' + value:24s} {int(fam.sum()):7d}  {full:10.3f}  {out:14.3f}  "
            f"{full - out:+.3f}",
            flush=True,
        )


def _rows(ev: CorpusEvidence, keep: NDArray[np.bool_]) -> CorpusEvidence:
    """The windows of ``ev`` where ``keep`` holds."""
    fam = {k: tuple(np.array(v)[keep].tolist()) for k, v in ev.family.items()}
    rules = tuple(np.array(ev.rules)[keep].tolist())
    return CorpusEvidence(ev.x[keep], ev.y[keep], rules, fam, ev.samples[keep], 0)


def _judged_rows(shapes: CorpusShapes, keep: NDArray[np.bool_]) -> CorpusShapes:
    """The judged windows of ``shapes`` (the evidence's rows) where ``keep`` holds: families
    are known for those only."""
    rows = np.flatnonzero(shapes.judged)[keep]
    return CorpusShapes(shapes.channels[rows], shapes.scalars[rows], shapes.y[rows],
                        np.ones(rows.size, dtype=bool))  # fmt: skip


if __name__ == "__main__":
    main()
