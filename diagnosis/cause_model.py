"""The learned decision (issue 46): a gradient-boosted tree ensemble over the chain's evidence
(``evidence.FEATURES``), fitted on the simulated corpus (``simulator.corpus``) and evaluated
here in numpy, so that the diagnosis needs neither the fitting library nor its import time.

The ensemble is LightGBM's (Ke et al. 2017) multiclass model, exported node by node by
``plantcheck model fit`` into ``models/cause_model.npz`` (numpy arrays, no pickle). Its raw
scores are calibrated by one temperature (Guo et al. 2017) fitted on simulated windows of
seeds the trees never saw. Each input's contribution to a class is read along the decision
path (Saabas 2014: the change in a node's value that the split on that input made), so the
contributions and the trees' base values add up to the raw score exactly.

A model may also hold a small network that reads the window's shape (``signal_shape``), or
several fitted from other seeds whose log-probabilities are averaged: the trees' calibrated
log-probabilities and the network's are then blended, (1 − w)·log p_trees
+ w·log p_shape, and calibrated once more by a second temperature, both fitted on the
calibration seed (a weighted product of experts, Hinton 2002; Guo et al. 2017).
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_shape import ShapeInput, ShapeNet, shape_log_probabilities

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
IndexArray = NDArray[np.int32]
BoolArray = NDArray[np.bool_]

CLAMP_SUPPORT = 0.9
"""The largest share of a window with OP at an output limit that the corpus draws (a saturated
window is drawn again beyond it: ``simulator.corpus``): a window clamped for longer, often a
valve at its limit all hour, holds no window the model was fitted on, and the trees and the
networks read its constant OP as nothing they learned (issue 25's plant windows: sticky, with
p = 1.00, or ok). The chain does not ask the model there (``chain._within_corpus``)."""

MODEL_FILE = "cause_model.npz"
"""The shipped model, in the package folder ``diagnosis/models``."""


@dataclass(frozen=True)
class _Walk:
    """A model's nodes laid out for walking, level by level: the nodes at depth d of every
    tree form one block, in tree order, and a leaf above the last level is carried down as a
    copy of itself, so all trees take the same number of steps and each step reads its block
    from front to back. The tree-major order ``plantcheck model fit`` writes sends each of the
    3,600 trees' steps to another part of a 10 MB array; in the chain, whose other arrays have
    pushed the model out of the processor's caches, that made the walk 1.4 ms instead of the
    0.4 it takes alone; 0.7-0.8 ms in this order (``benchmarks/diagnosis_speed.py --stages``).
    Where a missing input goes is decided once per node; each step's contribution (Saabas
    2014: the value gained from parent to child, credited to the parent's class × input) is
    laid out at the child, so the walk reads it with the indices it already holds; ``base``
    is each class's sum of its trees' root values, the same for every input."""

    threshold: FloatArray
    reads: IndexArray
    """Where each node reads its input in ``_Walk.inputs``: its input, in the copy that sends
    a missing value where the node does (LightGBM decides that once per node)."""
    children: IndexArray
    """(2 × slots,): the slot a node goes to when it goes right (at 2·slot) or left (at
    2·slot + 1), interleaved so that one ``take`` of ``2·slot + went_left`` reads it: half the
    time of a two-dimensional fancy index (3,600 trees, 5 steps: 90 µs against 180)."""
    value: FloatArray
    step_cell: IndexArray
    """The contribution cell (class × input) of the step into each slot: its parent's tree
    class and input (a root's is 0, never read)."""
    step_gain: FloatArray
    """The value gained on the step into each slot: its value less its parent's (0 at a
    root), as the walk subtracted it before."""
    roots: IndexArray
    base: FloatArray

    @staticmethod
    def inputs(x: FloatArray) -> FloatArray:
        """``x`` twice, a missing input (NaN) read as +inf in the first copy and as −inf in
        the second: ``x <= threshold`` then sends it right or left with no test for NaN on
        the walk (every threshold is finite)."""
        nan = np.isnan(x)
        return np.concatenate((np.where(nan, np.inf, x), np.where(nan, -np.inf, x)))


def _walk_layout(model: CauseModel) -> _Walk:
    """``model``'s walk layout; each tree's nodes follow its root up to the next tree's root
    (``plantcheck model fit`` writes them depth first, tree after tree). Built once per
    process, on its first decision: 20-45 ms of a one-record ``plantcheck diagnose``, so the
    slots' indices are made in 32 bits from the start and each array is gathered once."""
    n_feat = np.int32(len(model.features))
    leaf = model.feature < 0
    per_tree = np.diff(np.append(model.roots, leaf.size))
    class_of = np.repeat(model.tree_class.astype(np.int32), per_tree)
    levels = [model.roots]
    kids: list[tuple[IntArray, IntArray]] = []
    for _ in range(model.depth - 1):
        cur = levels[-1]
        on_leaf = leaf[cur]
        inner = ~on_leaf
        width = inner.astype(np.int64) + 1
        first = np.cumsum(width) - width
        nxt = np.empty(int(first[-1] + width[-1]), dtype=np.int64)
        nxt[first] = np.where(on_leaf, cur, model.left[cur])
        nxt[first[inner] + 1] = model.right[cur[inner]]
        kids.append((first + inner, first))
        levels.append(nxt)
    starts = np.cumsum([0] + [lv.size for lv in levels])
    total = int(starts[-1])
    # indices in 32 bits: the layout is a tenth of a process' memory, and the walk reads them
    # as fast as 64-bit ones; a slot of the last level is its own child on either side
    children = np.empty((2, total), dtype=np.int32)
    for d, (right, left) in enumerate(kids):
        children[0, starts[d] : starts[d + 1]] = right + starts[d + 1]
        children[1, starts[d] : starts[d + 1]] = left + starts[d + 1]
    children[:, starts[-2] :] = np.arange(starts[-2], total, dtype=np.int32)
    slot = np.concatenate(levels)
    feature = np.maximum(model.feature[slot], 0).astype(np.int32)  # a leaf's -1 reads input 0
    missing_left = np.where(model.nan_as_zero, model.threshold >= 0.0, model.default_left)[slot]
    if not np.all(np.isfinite(model.threshold[~leaf])):
        raise ValueError("a tree splits at an infinite threshold: the walk reads NaN as ±inf")
    value = model.value[slot]
    # each slot's parent: the slot whose right or left child it is (a carried leaf's copy is
    # both children of its leaf); a root's step is never read
    parent = np.zeros(total, dtype=np.int32)
    above = np.arange(starts[-2], dtype=np.int32)
    parent[children[0, : above.size]] = above
    parent[children[1, : above.size]] = above
    step_cell = (class_of[slot] * n_feat + feature)[parent]
    step_gain = value - value[parent]
    step_cell[: starts[1]] = 0
    step_gain[: starts[1]] = 0.0
    return _Walk(
        threshold=model.threshold[slot],
        reads=missing_left * n_feat + feature,
        children=np.ascontiguousarray(children.T).ravel(),
        value=value,
        step_cell=step_cell,
        step_gain=step_gain,
        roots=np.arange(model.roots.size, dtype=np.int32),
        base=np.bincount(
            model.tree_class, weights=model.value[model.roots], minlength=len(model.classes)
        ).astype(np.float64),
    )


@dataclass(frozen=True, eq=False)
class CauseModel:
    """A multiclass tree ensemble, every tree's nodes in flat arrays (global node indices).

    ``feature`` is the split input of each node (-1 on a leaf), ``threshold`` its cut
    (``x <= threshold`` goes left), ``default_left`` where a missing input goes, ``nan_as_zero``
    whether a missing input is read as 0 first (LightGBM's ``missing_type`` None), ``value``
    the node's output (a leaf's, or an inner node's own average). ``roots`` and
    ``tree_class`` give each tree's first node and the class it scores.
    """

    classes: tuple[str, ...]
    features: tuple[str, ...]
    feature: IntArray
    threshold: FloatArray
    left: IntArray
    right: IntArray
    default_left: BoolArray
    nan_as_zero: BoolArray
    value: FloatArray
    roots: IntArray
    tree_class: IntArray
    depth: int
    temperature: float
    meta: dict[str, object]
    shape: ShapeNet | None = None
    """The shape network blended with the trees (None: the trees decide alone)."""
    shape_more: tuple[ShapeNet, ...] = ()
    """Further networks fitted like ``shape`` from other seeds, on the same windows: their
    log-probabilities are averaged with its own (a deep ensemble, Lakshminarayanan et al.
    2017), so one draw's accidents weigh less."""
    shape_weight: float = 0.0
    """w: the network's weight in the blend of log-probabilities."""
    blend_temperature: float = 1.0
    """The blend's own softmax temperature."""
    shape_base: tuple[float, ...] = ()
    """The network's mean log-probability of each class over the calibration windows: what
    it gives an average window, against which its reading of one is a move (as the trees'
    contributions are moves from their base values)."""

    def to_arrays(self) -> dict[str, NDArray[np.generic]]:
        """The arrays ``np.savez`` writes (the metadata as UTF-8 JSON bytes)."""
        head = {"classes": self.classes, "features": self.features, "depth": self.depth,
                "temperature": self.temperature, "meta": self.meta,
                "shape_weight": self.shape_weight,
                "blend_temperature": self.blend_temperature,
                "shape_base": list(self.shape_base)}  # fmt: skip
        shape = {} if self.shape is None else self.shape.to_arrays(SHAPE_PREFIX)
        for k, net in enumerate(self.shape_more, start=2):
            shape |= net.to_arrays(f"shape{k}_")
        return {
            **shape,
            "head": np.frombuffer(json.dumps(head).encode(), dtype=np.uint8),
            # node indices fit 32 bits and inputs 16 (``load_cause_model`` widens them again)
            "feature": self.feature.astype(np.int16),
            "threshold": self.threshold,
            "left": self.left.astype(np.int32),
            "right": self.right.astype(np.int32),
            "default_left": self.default_left,
            "nan_as_zero": self.nan_as_zero,
            "value": self.value,
            "roots": self.roots.astype(np.int32),
            "tree_class": self.tree_class.astype(np.int16),
        }

    @cached_property
    def walk(self) -> _Walk:
        """The nodes laid out for ``decide`` (built on first use)."""
        return _walk_layout(self)


@dataclass(frozen=True)
class Decision:
    """The model's reading of one window: calibrated probabilities per class, the raw scores,
    and each input's contribution to each class's raw score (classes × inputs)."""

    probabilities: FloatArray
    raw: FloatArray
    base: FloatArray
    contributions: FloatArray
    shape_probabilities: FloatArray | None = None
    """The shape network's own probabilities, where it was blended in."""


def load_cause_model(path: Path) -> CauseModel:
    """Read a model written by ``plantcheck model fit`` (``np.load`` without pickle); a file
    that lacks an array the model needs (written by another version) is a ValueError naming
    it and the command that rebuilds the file."""
    try:
        return _read_model(path)
    except KeyError as exc:
        raise ValueError(
            f"{path}: the model file has no array {exc.args[0]!r} (written by another version of "
            "plantcheck?): rebuild it with `plantcheck model fit --out FILE`"
        ) from exc


def _read_model(path: Path) -> CauseModel:
    with np.load(path, allow_pickle=False) as z:
        head = json.loads(bytes(z["head"]).decode())
        return CauseModel(
            classes=tuple(head["classes"]),
            features=tuple(head["features"]),
            feature=z["feature"].astype(np.int64),
            threshold=z["threshold"].astype(np.float64),
            left=z["left"].astype(np.int64),
            right=z["right"].astype(np.int64),
            default_left=z["default_left"].astype(bool),
            nan_as_zero=z["nan_as_zero"].astype(bool),
            value=z["value"].astype(np.float64),
            roots=z["roots"].astype(np.int64),
            tree_class=z["tree_class"].astype(np.int64),
            depth=int(head["depth"]),
            temperature=float(head["temperature"]),
            meta=dict(head.get("meta") or {}),
            # the open file, not dict(z): that decompressed every array again (the trees' 5 MB,
            # 20-45 ms of a one-record `plantcheck diagnose`)
            shape=ShapeNet.from_arrays(z, SHAPE_PREFIX) if _has_shape(z, SHAPE_PREFIX) else None,
            shape_more=_more_shapes(z),
            shape_weight=float(head.get("shape_weight", 0.0)),
            blend_temperature=float(head.get("blend_temperature", 1.0)),
            shape_base=tuple(float(v) for v in head.get("shape_base", ())),
        )


SHAPE_PREFIX = "shape_"
"""The shape network's arrays in a model file are named with this prefix (the further
networks': ``shape2_``, ``shape3_``...)."""


def _has_shape(z: np.lib.npyio.NpzFile, prefix: str) -> bool:
    return f"{prefix}scalar_mean" in z.files


def _more_shapes(z: np.lib.npyio.NpzFile) -> tuple[ShapeNet, ...]:
    """The further networks ``shape2_``, ``shape3_``... of a model file, up to the first
    missing."""
    prefixes = itertools.takewhile(
        lambda p: _has_shape(z, p), (f"shape{k}_" for k in itertools.count(2))
    )
    return tuple(ShapeNet.from_arrays(z, p) for p in prefixes)


SHIPPED_MODEL = Path(__file__).with_name("models") / MODEL_FILE
"""The shipped model's path (``plantcheck model fit`` writes it by default)."""


@lru_cache(maxsize=1)
def shipped_cause_model() -> CauseModel | None:
    """The model shipped with the package, or None when the file is absent (a build that
    has not fitted one yet: the chain's rules then decide alone)."""
    return load_cause_model(SHIPPED_MODEL) if SHIPPED_MODEL.is_file() else None


def decide(model: CauseModel, x: FloatArray, shape: ShapeInput | None = None) -> Decision:
    """Walk every tree at once for the input vector ``x`` (``model.features`` order, NaN =
    not computed): raw scores per class, their Saabas contributions, and the probabilities
    softmax(raw / temperature), blended with the shape network's reading of ``shape`` where
    the model has one. The cost is a few numpy calls per level of the deepest tree,
    whatever the number of trees; the contributions are summed once, over the whole path."""
    n_cls, n_feat = len(model.classes), len(model.features)
    w = model.walk
    inputs = w.inputs(x)
    idx = w.roots
    path = []
    for _ in range(model.depth - 1):
        go_left = inputs.take(w.reads.take(idx)) <= w.threshold.take(idx)
        idx = w.children.take(2 * idx + go_left)
        path.append(idx)
    went = np.concatenate(path) if path else idx[:0]
    contrib = np.asarray(
        np.bincount(
            w.step_cell.take(went), weights=w.step_gain.take(went), minlength=n_cls * n_feat
        ),
        dtype=np.float64,
    ).reshape(n_cls, n_feat)
    raw = np.bincount(model.tree_class, weights=w.value.take(idx), minlength=n_cls).astype(
        np.float64
    )
    p = calibrated(raw, model.temperature)
    if model.shape is None or shape is None:
        return Decision(p, raw, w.base.copy(), contrib)
    log_shape = shape_reading(model.shape, model.shape_more, shape)
    p = blended(safe_log(p), log_shape, model.shape_weight, model.blend_temperature)
    return Decision(p, raw, w.base.copy(), contrib, np.exp(log_shape))


def shape_reading(first: ShapeNet, more: tuple[ShapeNet, ...], x: ShapeInput) -> FloatArray:
    """The networks' log-probabilities of the window ``x``: the first network's own, or,
    with ``more``, the log of their normalised geometric mean (the mean of their
    log-probabilities, normalised again)."""
    log_first = shape_log_probabilities(first, x)
    if not more:
        return log_first
    mean = np.mean([log_first, *(shape_log_probabilities(net, x) for net in more)], axis=0)
    return safe_log(calibrated(mean, 1.0))


def safe_log(p: FloatArray) -> FloatArray:
    """log p, a probability that underflowed to 0 read as 1e-300 (a blend weight of 0 or 1
    would otherwise multiply −inf by 0)."""
    out: FloatArray = np.log(np.maximum(p, 1e-300))
    return out


def blended(
    log_trees: FloatArray, log_shape: FloatArray, weight: float, temperature: float
) -> FloatArray:
    """softmax(((1 − weight)·log_trees + weight·log_shape) / temperature), per row."""
    return calibrated((1.0 - weight) * log_trees + weight * log_shape, temperature)


def calibrated(raw: FloatArray, temperature: float) -> FloatArray:
    """softmax(raw / temperature) over the last axis: the calibrated class probabilities of
    one window's raw scores, or of each row of many."""
    z = raw / temperature
    p = np.exp(z - z.max(axis=-1, keepdims=True))
    out: FloatArray = p / p.sum(axis=-1, keepdims=True)
    return out
