"""``plantcheck model fit``: the learned decision rebuilt from the simulated corpus (issue 46).

Steps: draw the corpus windows (``simulator.corpus``) of three seeds apart (fit, calibration,
check), run the chain's tests on each (``diagnosis.chain.chain_evidence``), fit LightGBM's
multiclass gradient-boosted trees (Ke et al. 2017) on the first, fit one softmax temperature
(Guo et al. 2017) on the second, fit the shape networks on the first and their blend with the
trees on the second (``service.shape_model_fit``), report the third, and export it all into
the numpy file the diagnosis reads (``diagnosis.cause_model``). Real plant records play no
part: they are test sets only.

LightGBM and PyTorch are imported by the fit only (the ``fit`` extra), so the CLI's other
commands never pay their import time.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from plantcheck.diagnosis.cause_model import (
    CauseModel,
    blended,
    calibrated,
    decide,
    safe_log,
    shape_reading,
)
from plantcheck.diagnosis.chain import chain_evidence
from plantcheck.diagnosis.evidence import EVIDENCE_VERSION, FEATURE_NAMES, evidence_vector
from plantcheck.diagnosis.signal_shape import ShapeInput
from plantcheck.service.corpus_cache import CorpusKind, corpus_file, corpus_files
from plantcheck.service.shape_model_fit import (
    EPOCHS,
    SHAPE_VERSION,
    SHAPES_FILE,
    CorpusShapes,
    corpus_shapes,
    fit_blend,
    fit_shape_net,
)
from plantcheck.service.shape_model_fit import FIT_THREADS as SHAPE_THREADS
from plantcheck.simulator.corpus import (
    CLASSES,
    CORPUS_VERSION,
    FAMILY_KEYS,
    CorpusCase,
)
from plantcheck.simulator.loop import LoopRecord

FIT_SEED, CALIBRATION_SEED, CHECK_SEED = 101, 202, 303
"""The corpus seeds of the fit, the temperature and the check figures: never the same."""

LGBM_PARAMS: dict[str, Any] = {
    "objective": "multiclass",
    "learning_rate": 0.1,
    "num_leaves": 31,
    "max_depth": 5,
    "min_data_in_leaf": 20,
    "bagging_fraction": 0.8,
    "bagging_freq": 1,
    "feature_fraction": 0.8,
    "lambda_l2": 1.0,
    "verbose": -1,
    "deterministic": True,
    "force_col_wise": True,
}
"""LightGBM's settings: trees of at most 5 levels, row and column subsampling (the library's
usual guards against fitting the corpus' accidents). With 64,000 fit windows these trees read
more than 250 rounds of 15 leaves did (0.848 -> 0.860 on the calibration seed; with 16,000 the
trees were not the limit); the depth bound keeps the walk to six steps, so 3,600 trees cost
the chain 0.3 ms (benchmarks/README.md)."""

ROUNDS = 600
"""Boosting rounds (trees per class)."""

FIT_THREADS = 2
"""LightGBM's threads, fixed whatever the machine's cores, with its ``deterministic`` and
``force_col_wise`` settings: the histograms' sums depend on how the rows are split between
threads, and the row/column choice on a timing test, so a fit on every core gave other trees
on a machine with another core count (the twenty-fifth session's rebuild). Fixed, the same
cached evidence gives the same model file on 1 or 2 cores (checked by hand: three fits, one
confined to one core, wrote the same bytes; benchmarks/README.md) at about 40 s on 2."""

FIT_WINDOWS = 64_000
"""The default number of fit windows (``plantcheck model fit``, the accuracy benchmark)."""

SIDE_WINDOWS = 8_000
"""At most this many windows of the calibration and of the check seed: a temperature and a
figure to two decimals need no more, and each window drawn costs the fit's time."""


SHAPE_WINDOW_FACTOR = 4
"""The shape network reads this many times the trees' fit windows (the first ones of the fit
seed, the trees' own among them): on 32,000, 64,000, 128,000 and 256,000 windows it read the
check seed at 0.825, 0.853, 0.880 and 0.896 alone, still learning where the trees no longer do
(benchmarks/README.md)."""


TREE_WINDOW_FACTOR = 4
"""The trees too read this many times the fit windows (the network's windows, whose
evidence the fit then computes as well): on the 256,000 windows they gained 0.002-0.008 on
each of seven seeds against 64,000 (forty-sixth session, benchmarks/README.md)."""

SHAPE_NETWORKS = 2
"""Shape networks fitted on the same windows from seeds ``shape_seed``, ``shape_seed`` + 1...
and averaged (``CauseModel.shape_more``)."""


def side_windows(windows: int) -> int:
    """Windows of the calibration and of the check seed beside ``windows`` fit windows: a
    quarter as many, 60 to ``SIDE_WINDOWS``."""
    return min(SIDE_WINDOWS, max(60, windows // 4))


@dataclass(frozen=True)
class CorpusEvidence:
    """The evidence of a corpus' windows: inputs (windows × ``FEATURE_NAMES``), true class
    index, the rules' causes, families and loop types; windows with nothing to weigh are left
    out (``skipped`` counts them)."""

    x: NDArray[np.float64]
    y: NDArray[np.int64]
    rules: tuple[str, ...]
    family: dict[str, tuple[str, ...]]
    samples: NDArray[np.int64]
    skipped: int


def _evidence(
    seed: int, index: int, case: CorpusCase, rec: LoopRecord
) -> tuple[int, str, list[float] | None, dict[str, str], int]:
    try:
        rules, ev = chain_evidence(rec.pv, rec.op, case.config.sample_time_s, sp=rec.sp,
                                   loop_type=case.loop_type)  # fmt: skip
    except Exception as exc:
        # a chain that fails on a simulated window is a bug: name the window that shows it
        raise RuntimeError(f"corpus seed {seed} window {index} ({case.family}): {exc!r}") from exc
    vec = None if ev is None else evidence_vector(ev).tolist()
    return CLASSES.index(case.cause), rules, vec, case.family, case.config.n_samples


def corpus_evidence(
    seed: int,
    n: int,
    jobs: int | None = None,
    progress: Callable[[str], None] | None = None,
    cache: Path | None = None,
) -> CorpusEvidence:
    """The evidence of windows 0..n-1 of corpus ``seed``, computed on ``jobs`` processes (all
    cores by default) and kept in ``cache`` (a folder) when given; a cached file of fewer
    windows of the seed is read as their start (``service.corpus_cache``)."""
    return corpus_file(EVIDENCE_FILE, seed, n, jobs, progress, cache)


def corpus_evidence_and_shapes(
    seed: int,
    n: int,
    jobs: int | None = None,
    progress: Callable[[str], None] | None = None,
    cache: Path | None = None,
) -> tuple[CorpusEvidence, CorpusShapes]:
    """``corpus_evidence`` and ``corpus_shapes`` of the same windows, each window simulated
    once for both: about 40 % less drawing than the two one after the other."""
    ev, shapes = corpus_files([EVIDENCE_FILE, SHAPES_FILE], seed, n, jobs, progress, cache)
    return cast(CorpusEvidence, ev), cast(CorpusShapes, shapes)


def _evidence_stem(seed: int) -> str:
    return f"corpus-v{CORPUS_VERSION}.{EVIDENCE_VERSION}-{seed}-"


def _save_evidence(path: Path, ev: CorpusEvidence) -> None:
    np.savez_compressed(
        path, x=ev.x, y=ev.y, samples=ev.samples, skipped=np.array(ev.skipped),
        rules=np.frombuffer(json.dumps(ev.rules).encode(), dtype=np.uint8),
        family=np.frombuffer(json.dumps(ev.family).encode(), dtype=np.uint8),
    )  # fmt: skip


def _load_evidence(path: Path) -> CorpusEvidence:
    with np.load(path, allow_pickle=False) as z:
        fam = json.loads(bytes(z["family"]).decode())
        return CorpusEvidence(z["x"], z["y"], tuple(json.loads(bytes(z["rules"]).decode())),
                              {k: tuple(v) for k, v in fam.items()}, z["samples"],
                              int(z["skipped"]))  # fmt: skip


def _joined(head: CorpusEvidence, tail: CorpusEvidence) -> CorpusEvidence:
    """The windows of ``head``, then those of ``tail``."""
    return CorpusEvidence(
        np.concatenate((head.x, tail.x)),
        np.concatenate((head.y, tail.y)),
        head.rules + tail.rules,
        {k: head.family[k] + tail.family[k] for k in head.family},
        np.concatenate((head.samples, tail.samples)),
        head.skipped + tail.skipped,
    )


_EvidenceRow = tuple[int, str, list[float] | None, dict[str, str], int]
"""One window's class, rules' cause, evidence (None: nothing to weigh), families, samples."""


class _EvidenceRows:
    """The evidence of windows as they are read; those with nothing to weigh are counted."""

    def __init__(self, count: int) -> None:
        self.rows: list[list[float]] = []
        self.ys: list[int] = []
        self.rules: list[str] = []
        self.fams: dict[str, list[str]] = {k: [] for k in FAMILY_KEYS}
        self.lengths: list[int] = []
        self.skipped = 0

    def add(self, row: _EvidenceRow) -> None:
        y, rule, vec, family, ns = row
        if vec is None:
            self.skipped += 1
            return
        self.rows.append(vec)
        self.ys.append(y)
        self.rules.append(rule)
        self.lengths.append(ns)
        for k in FAMILY_KEYS:
            self.fams[k].append(family[k])

    def result(self) -> CorpusEvidence:
        return CorpusEvidence(
            np.array(self.rows, dtype=np.float64).reshape(-1, len(FEATURE_NAMES)),
            np.array(self.ys, dtype=np.int64),
            tuple(self.rules),
            {k: tuple(v) for k, v in self.fams.items()},
            np.array(self.lengths, dtype=np.int64),
            self.skipped,
        )


EVIDENCE_FILE: CorpusKind[_EvidenceRow, CorpusEvidence] = CorpusKind(
    _evidence_stem, _evidence, _EvidenceRows, _joined, _load_evidence, _save_evidence
)
"""The chain's evidence of a corpus' windows, as the fit caches it."""


def fit_trees(
    x: NDArray[np.float64],
    y: NDArray[np.int64],
    seed: int = 0,
    changed: dict[str, Any] | None = None,
    rounds: int = ROUNDS,
) -> Any:
    """LightGBM's multiclass booster fitted on ``x``, ``y`` (its native API: no scikit-learn);
    ``changed`` overrides entries of ``LGBM_PARAMS`` (benchmarks/cause_model_limits.py)."""
    import lightgbm

    params = {**LGBM_PARAMS, **(changed or {}), "num_class": len(CLASSES), "seed": seed,
              "num_threads": FIT_THREADS}  # fmt: skip
    return lightgbm.train(params, lightgbm.Dataset(x, label=y), num_boost_round=rounds)


def export_trees(booster: Any, temperature: float, meta: dict[str, object]) -> CauseModel:
    """The booster's trees as the flat arrays ``diagnosis.cause_model`` walks."""
    dump = booster.dump_model()
    n_cls = int(dump["num_class"])
    feature: list[int] = []
    threshold: list[float] = []
    left: list[int] = []
    right: list[int] = []
    default_left: list[bool] = []
    nan_as_zero: list[bool] = []
    value: list[float] = []
    roots: list[int] = []
    tree_class: list[int] = []
    depth = 0

    def add(node: dict[str, Any], level: int) -> int:
        nonlocal depth
        depth = max(depth, level)
        i = len(feature)
        feature.append(-1)
        threshold.append(0.0)
        left.append(-1)
        right.append(-1)
        default_left.append(False)
        nan_as_zero.append(False)
        if "leaf_value" in node:
            value.append(float(node["leaf_value"]))
            return i
        if node.get("decision_type", "<=") != "<=":
            raise ValueError(f"unsupported split {node.get('decision_type')!r}")
        value.append(float(node["internal_value"]))
        feature[i] = int(node["split_feature"])
        threshold[i] = float(node["threshold"])
        default_left[i] = bool(node["default_left"])
        nan_as_zero[i] = node.get("missing_type") == "None"
        left[i] = add(node["left_child"], level + 1)
        right[i] = add(node["right_child"], level + 1)
        return i

    for tree in dump["tree_info"]:
        roots.append(add(tree["tree_structure"], 1))
        tree_class.append(int(tree["tree_index"]) % n_cls)
    return CauseModel(
        classes=CLASSES,
        features=FEATURE_NAMES,
        feature=np.array(feature, dtype=np.int32).astype(np.int64),
        threshold=np.array(threshold),
        left=np.array(left, dtype=np.int64),
        right=np.array(right, dtype=np.int64),
        default_left=np.array(default_left),
        nan_as_zero=np.array(nan_as_zero),
        value=np.array(value),
        roots=np.array(roots, dtype=np.int64),
        tree_class=np.array(tree_class, dtype=np.int64),
        depth=depth,
        temperature=temperature,
        meta=meta,
    )


def raw_scores(model: CauseModel, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """The model's raw class scores for every row of ``x``."""
    return np.array([decide(model, row).raw for row in x], dtype=np.float64).reshape(
        -1, len(model.classes)
    )


def fit_temperature(raw: NDArray[np.float64], y: NDArray[np.int64]) -> float:
    """The softmax temperature minimising the negative log-likelihood of ``y`` (Guo et al.
    2017): one number, so the ranking of causes never changes."""

    def nll(log_t: float) -> float:
        z = raw / math.exp(log_t)
        z = z - z.max(axis=1, keepdims=True)
        logp = z - np.log(np.exp(z).sum(axis=1, keepdims=True))
        return float(-np.mean(logp[np.arange(y.size), y]))

    res = minimize_scalar(nll, bounds=(math.log(0.2), math.log(5.0)), method="bounded")
    return float(math.exp(res.x))


def macro_f1(
    y: NDArray[np.int64], pred: NDArray[np.int64], n_cls: int
) -> tuple[float, list[float]]:
    """Macro-averaged F1 and each class's F1."""
    f1s = []
    for c in range(n_cls):
        tp = float(np.sum((pred == c) & (y == c)))
        fp = float(np.sum((pred == c) & (y != c)))
        fn = float(np.sum((pred != c) & (y == c)))
        f1s.append(2 * tp / (2 * tp + fp + fn) if tp else 0.0)
    return float(np.mean(f1s)), f1s


def paired_macro_f1_difference(
    y: NDArray[np.int64],
    pred: NDArray[np.int64],
    other: NDArray[np.int64],
    n_cls: int,
    resamples: int = 500,
    seed: int = 0,
) -> tuple[float, float]:
    """Macro-F1 of ``pred`` less that of ``other`` on the same windows, and the difference's
    standard error by a paired bootstrap (Efron & Tibshirani 1993: both read on each resample
    of the windows, so what the windows share cancels). Two fits of one corpus differ by about
    0.002 on 8,000 windows (forty-fourth session): a rule that asks a refit to read at least
    the shipped file on one seed is a coin toss below that."""
    diff = macro_f1(y, pred, n_cls)[0] - macro_f1(y, other, n_cls)[0]
    if resamples < 2 or y.size == 0:
        return diff, math.nan
    rng = np.random.default_rng(seed)
    draws = [
        macro_f1(y[i], pred[i], n_cls)[0] - macro_f1(y[i], other[i], n_cls)[0]
        for i in (rng.integers(0, y.size, y.size) for _ in range(resamples))
    ]
    return diff, float(np.std(draws))


def reliability(
    p: NDArray[np.float64], y: NDArray[np.int64], bins: int = 10
) -> list[tuple[float, float, int]]:
    """(mean probability, share right, windows) of the top class per equal-width bin of its
    probability: the reliability diagram's points (Guo et al. 2017)."""
    conf = p.max(axis=1)
    right = p.argmax(axis=1) == y
    out = []
    for lo, hi in itertools.pairwise(np.linspace(0.0, 1.0, bins + 1)):
        m = (conf > lo) & (conf <= hi)
        if m.any():
            out.append((float(conf[m].mean()), float(right[m].mean()), int(m.sum())))
    return out


def expected_calibration_error(
    p: NDArray[np.float64], y: NDArray[np.int64], bins: int = 10
) -> float:
    """ECE: the reliability bins' gaps between probability and share right, weighted by their
    windows (Guo et al. 2017)."""
    return sum(n * abs(acc - conf) for conf, acc, n in reliability(p, y, bins)) / max(y.size, 1)


@dataclass(frozen=True)
class FitReport:
    """The figures of one fit on the check seed."""

    model: CauseModel
    windows: dict[str, int]
    temperature: float
    macro_f1: float
    class_f1: dict[str, float]
    ece: float
    rules_macro_f1: float
    trees_macro_f1: float
    """The trees' own figure, before the shape network is blended in."""


def fit_model(
    windows: int,
    jobs: int | None = None,
    progress: Callable[[str], None] | None = None,
    cache: Path | None = None,
    seeds: Sequence[int] = (FIT_SEED, CALIBRATION_SEED, CHECK_SEED),
    tree_seed: int = 0,
    shape: bool = True,
    shape_seed: int = 0,
    networks: int = SHAPE_NETWORKS,
) -> FitReport:
    """Fit on ``windows`` windows of the fit seed, calibrate and check on
    ``side_windows(windows)`` of the other two; the exported model and its check figures.
    ``tree_seed``: LightGBM's seed for its row and column subsampling; ``shape``: fit the
    shape networks and blend them in (``service.shape_model_fit``), ``networks`` of them,
    the k-th's weights drawn and its batches shuffled from ``shape_seed`` + k. The trees
    read ``TREE_WINDOW_FACTOR`` × ``windows`` windows of the fit seed."""
    say = progress or (lambda _m: None)
    fit_s, cal_s, chk_s = seeds
    small = side_windows(windows)
    # each window simulated once for the trees and the networks where both read it
    both = shape and TREE_WINDOW_FACTOR == SHAPE_WINDOW_FACTOR
    fit_shapes = cal_shapes = chk_shapes = None
    if both:
        fit, fit_shapes = corpus_evidence_and_shapes(fit_s, TREE_WINDOW_FACTOR * windows,
                                                     jobs, say, cache)  # fmt: skip
        cal, cal_shapes = corpus_evidence_and_shapes(cal_s, small, jobs, say, cache)
        chk, chk_shapes = corpus_evidence_and_shapes(chk_s, small, jobs, say, cache)
    else:
        fit = corpus_evidence(fit_s, TREE_WINDOW_FACTOR * windows, jobs, say, cache)
        cal = corpus_evidence(cal_s, small, jobs, say, cache)
        chk = corpus_evidence(chk_s, small, jobs, say, cache)
    say(f"fitting {ROUNDS} rounds on {fit.y.size} windows")
    booster = fit_trees(fit.x, fit.y, seed=tree_seed)
    meta: dict[str, object] = {
        "library": "lightgbm",
        "corpus_version": CORPUS_VERSION,
        "evidence_version": EVIDENCE_VERSION,
        "params": {**LGBM_PARAMS, "rounds": ROUNDS, "num_threads": FIT_THREADS},
        "seeds": {"fit": fit_s, "calibration": cal_s, "check": chk_s, "trees": tree_seed},
        "windows": {
            "fit": int(fit.y.size),
            "calibration": int(cal.y.size),
            "check": int(chk.y.size),
        },
    }
    model = export_trees(booster, 1.0, meta)
    # the export must score exactly as the library does
    ref = booster.predict(cal.x[:50], raw_score=True)
    mine = raw_scores(model, cal.x[:50])
    if not np.allclose(ref, mine, atol=1e-6):
        raise RuntimeError(f"exported trees disagree with LightGBM: {np.abs(ref - mine).max():g}")
    temperature = fit_temperature(raw_scores(model, cal.x), cal.y)
    model = export_trees(booster, temperature, meta)
    trees_f1, _ = macro_f1(chk.y, raw_scores(model, chk.x).argmax(axis=1), len(CLASSES))
    if shape:
        if fit_shapes is None or cal_shapes is None:
            fit_shapes = corpus_shapes(fit_s, SHAPE_WINDOW_FACTOR * windows, jobs, say, cache)
            cal_shapes = corpus_shapes(cal_s, small, jobs, say, cache)
        model = with_blend(
            with_networks(model, fit_shapes, networks, shape_seed, say),
            cal, cal_shapes, fit_shapes.y.size, seed=shape_seed,
        )  # fmt: skip
        say(f"blend: shape network weight {model.shape_weight}, "
            f"temperature {model.blend_temperature:.3f}")  # fmt: skip
    if shape and chk_shapes is None:
        chk_shapes = corpus_shapes(chk_s, small, jobs, say, cache)
    p = model_probabilities(model, chk, chk_shapes)
    pred = p.argmax(axis=1)
    mf1, f1s = macro_f1(chk.y, pred, len(CLASSES))
    rule_pred = np.array([CLASSES.index(r) if r in CLASSES else -1 for r in chk.rules])
    rules_f1, _ = macro_f1(chk.y, rule_pred, len(CLASSES))
    return FitReport(
        model,
        {"fit": int(fit.y.size), "calibration": int(cal.y.size), "check": int(chk.y.size)},
        temperature,
        mf1,
        dict(zip(CLASSES, f1s, strict=True)),
        expected_calibration_error(p, chk.y),
        rules_f1,
        trees_f1,
    )


def save_model(model: CauseModel, path: Path) -> None:
    """Write the model as ``np.savez_compressed`` arrays (no pickle)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as fh:
        np.savez_compressed(fh, **model.to_arrays())  # type: ignore[arg-type]


def with_networks(
    model: CauseModel,
    shapes: CorpusShapes,
    networks: int,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> CauseModel:
    """``model`` with ``networks`` shape networks fitted on ``shapes``, the k-th from seed
    ``seed`` + k (a deep ensemble, Lakshminarayanan et al. 2017): the first is
    ``model.shape``, the others ``model.shape_more``. Their blend is not set here
    (``with_blend``)."""
    if networks < 1:
        raise ValueError(f"networks: {networks}; at least 1 network is needed")
    nets = [fit_shape_net(shapes, seed=seed + k, progress=progress) for k in range(networks)]
    return replace(model, shape=nets[0], shape_more=tuple(nets[1:]))


def with_blend(
    model: CauseModel,
    cal: CorpusEvidence,
    cal_shapes: CorpusShapes,
    fit_windows: int,
    seed: int = 0,
) -> CauseModel:
    """``model`` (trees and shape network) with the network's weight in the blend and the
    blend's temperature that the calibration windows (``cal``, ``cal_shapes``) give;
    ``fit_windows`` and ``seed``: the windows the network was fitted on and its seed (kept in
    the model's meta)."""
    log_trees = _log_trees(model, cal)
    log_shape = shape_log_probabilities_of(model, cal_shapes)
    weight, temperature = fit_blend(log_trees, log_shape, cal.y)
    shape_meta = {"version": SHAPE_VERSION, "library": "torch", "epochs": EPOCHS,
                  "threads": SHAPE_THREADS, "windows": int(fit_windows), "seed": seed,
                  "networks": 1 + len(model.shape_more)}  # fmt: skip
    return replace(model, shape_weight=weight, blend_temperature=temperature,
                   shape_base=tuple(log_shape.mean(axis=0).tolist()),
                   meta={**model.meta, "shape": shape_meta})  # fmt: skip


def _log_trees(model: CauseModel, ev: CorpusEvidence) -> NDArray[np.float64]:
    p = calibrated(raw_scores(model, ev.x), model.temperature)
    return safe_log(p)


def model_probabilities(
    model: CauseModel, ev: CorpusEvidence, shapes: CorpusShapes | None
) -> NDArray[np.float64]:
    """The model's class probabilities of ``ev``'s windows, as a diagnosis gives them: the
    trees', blended with the shape network's reading of ``shapes`` where the model has one."""
    log_trees = _log_trees(model, ev)
    if model.shape is None:
        return np.exp(log_trees)
    if shapes is None:
        raise ValueError("the model blends a shape network: give the windows' shapes")
    log_shape = shape_log_probabilities_of(model, shapes)
    if log_shape.shape[0] != ev.y.size:
        raise RuntimeError("the shapes and the evidence judge other windows")
    return blended(log_trees, log_shape, model.shape_weight, model.blend_temperature)


def shape_log_probabilities_of(model: CauseModel, shapes: CorpusShapes) -> NDArray[np.float64]:
    """The model's shape network's log-probabilities of the judged windows of ``shapes``
    (the rows ``corpus_evidence`` keeps, in order)."""
    net = model.shape
    if net is None:
        raise ValueError("the model has no shape network")
    rows = np.flatnonzero(shapes.judged)
    return np.array(
        [
            shape_reading(
                net,
                model.shape_more,
                ShapeInput(
                    shapes.channels[i].astype(np.float64), shapes.scalars[i].astype(np.float64)
                ),
            )
            for i in rows.tolist()
        ]
    ).reshape(-1, len(model.classes))
