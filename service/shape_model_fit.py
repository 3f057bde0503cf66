"""The shape network of the learned decision (``diagnosis.signal_shape``), fitted with PyTorch
on the simulated corpus, and its blend with the trees (issue 46).

PyTorch is imported here only (the ``fit`` extra). The fit is made repeatable: a fixed seed,
``FIT_THREADS`` threads and deterministic algorithms, so the same corpus gives the same
weights.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from plantcheck.diagnosis.cause_model import blended, safe_log
from plantcheck.diagnosis.chain import chain_shape_input
from plantcheck.diagnosis.signal_shape import SCALARS, SHAPE_SAMPLES, ShapeNet
from plantcheck.service.corpus_cache import CorpusKind, corpus_file
from plantcheck.simulator.corpus import (
    CLASSES,
    CORPUS_VERSION,
    CorpusCase,
)
from plantcheck.simulator.loop import LoopRecord

SHAPE_VERSION = 2
"""Raised whenever ``signal_shape.shape_input`` or what it is given changes: cached shapes
are then redrawn. Version 2: the window read through ``chain._prepare``, as the evidence."""

CHANNELS = (3, 32, 64, 96, 128)
"""The convolutions' channels, input first. Twice the width of the first networks (16, 32,
48, 64 with a dense layer of 64; fortieth session): on the 256,000 fit windows the network
alone read check seed 303 0.914 against 0.896 and the blend 0.934 against 0.925, for about
0.7 ms more of the chain per 3,600 samples on a 2-core machine whose chain takes 18-28 ms
(benchmarks/README.md)."""
KERNELS = (9, 7, 5, 5)
"""Their kernel lengths (stride 2 each: 512 points become 32)."""
HIDDEN = 128
"""The dense layer's width."""
EPOCHS = 15
"""Passes over the fit windows."""
BATCH = 128
"""Windows per gradient step."""
LEARNING_RATE = 2e-3
MAX_LEARNING_RATE = 3e-3
"""AdamW's (Loshchilov & Hutter 2019) rate as built; the one-cycle schedule (Smith 2018) takes
over, from ``MAX_LEARNING_RATE`` / 25 up to it and down again."""
WEIGHT_DECAY = 1e-4
FIT_THREADS = 2
"""PyTorch's threads, fixed whatever the machine, so that its sums run in the same order."""
BLEND_WEIGHTS = tuple(round(0.05 * k, 2) for k in range(21))
"""The network's weights in the blend tried on the calibration seed."""


@dataclass(frozen=True)
class CorpusShapes:
    """The shape inputs of a corpus' windows 0..n-1 (every window, judged or not), their
    class, and whether the chain judges the window (the rows ``corpus_evidence`` keeps)."""

    channels: NDArray[np.float16]
    scalars: NDArray[np.float32]
    y: NDArray[np.int64]
    judged: NDArray[np.bool_]


def _shape(
    seed: int, index: int, case: CorpusCase, rec: LoopRecord
) -> tuple[int, NDArray[np.float64], NDArray[np.float64], bool]:
    x, judged = chain_shape_input(
        rec.pv, rec.op, rec.sp, loop_type=case.loop_type, ts=case.config.sample_time_s
    )
    return CLASSES.index(case.cause), x.channels, x.scalars, judged


def corpus_shapes(
    seed: int,
    n: int,
    jobs: int | None = None,
    progress: Callable[[str], None] | None = None,
    cache: Path | None = None,
) -> CorpusShapes:
    """The shape inputs of windows 0..n-1 of corpus ``seed`` on ``jobs`` processes, kept in
    ``cache`` (a folder) when given: about 68 windows/s on 2 cores (2026-11-30). A window
    depends on its seed and index only, so the largest cached file of fewer windows of the
    same seed is read as their start and only the rest are drawn."""
    return corpus_file(SHAPES_FILE, seed, n, jobs, progress, cache, "shape windows")


def _joined(head: CorpusShapes, tail: CorpusShapes) -> CorpusShapes:
    """The windows of ``head``, then those of ``tail``."""
    return CorpusShapes(
        np.concatenate((head.channels, tail.channels)),
        np.concatenate((head.scalars, tail.scalars)),
        np.concatenate((head.y, tail.y)),
        np.concatenate((head.judged, tail.judged)),
    )


def _shapes_stem(seed: int) -> str:
    """A cached file's name less its window count and ``.npz``."""
    return f"shapes-v{CORPUS_VERSION}.{SHAPE_VERSION}-{seed}-"


def _load_shapes(path: Path) -> CorpusShapes:
    with np.load(path, allow_pickle=False) as z:
        return CorpusShapes(z["channels"], z["scalars"], z["y"], z["judged"])


def _save_shapes(path: Path, shapes: CorpusShapes) -> None:
    np.savez_compressed(path, channels=shapes.channels, scalars=shapes.scalars, y=shapes.y,
                        judged=shapes.judged)  # fmt: skip


_ShapeRow = tuple[int, NDArray[np.float64], NDArray[np.float64], bool]
"""One window's class, channels, scalars and whether the chain judges it."""


class _ShapeRows:
    """The shape inputs of ``count`` windows as they are read, in arrays made beforehand (the
    channels in float16, as ``shape_input`` rounded them: stored exactly)."""

    def __init__(self, count: int) -> None:
        self.shapes = CorpusShapes(
            np.zeros((count, 3, SHAPE_SAMPLES), dtype=np.float16),
            np.zeros((count, len(SCALARS)), dtype=np.float32),
            np.zeros(count, dtype=np.int64),
            np.zeros(count, dtype=bool),
        )
        self.count = 0

    def add(self, row: _ShapeRow) -> None:
        i, out = self.count, self.shapes
        out.y[i], out.channels[i], out.scalars[i], out.judged[i] = row
        self.count += 1

    def result(self) -> CorpusShapes:
        return self.shapes


SHAPES_FILE: CorpusKind[_ShapeRow, CorpusShapes] = CorpusKind(
    _shapes_stem, _shape, _ShapeRows, _joined, _load_shapes, _save_shapes
)
"""The shape inputs of a corpus' windows, as the fit caches them."""


def fit_shape_net(
    shapes: CorpusShapes, seed: int = 0, progress: Callable[[str], None] | None = None
) -> ShapeNet:
    """The network fitted on every window of ``shapes`` (cross-entropy, AdamW, a one-cycle
    schedule over ``EPOCHS`` epochs), batch normalisation folded into the convolutions."""
    import torch
    from torch import nn

    say = progress or (lambda _m: None)
    torch.set_num_threads(FIT_THREADS)
    torch.use_deterministic_algorithms(True)
    torch.manual_seed(seed)
    # a window the checks stop on after leaving a frozen transmitter's samples out as missing
    # (``window.frozen_pv``, since the fifty-second session) has no shape, NaN throughout: 15
    # of seed 101's 256,000, short interpolated or compressed records; it is fitted as a flat
    # one, as its missing scalars are, rather than turning every weight into NaN
    x = torch.nan_to_num(torch.tensor(shapes.channels.astype(np.float32)))
    s = torch.nan_to_num(torch.tensor(shapes.scalars))
    y = torch.tensor(shapes.y)
    mu, sd = s.mean(0), s.std(0) + 1e-6
    net = shape_module(nn, mu, sd)
    opt = torch.optim.AdamW(net.parameters(), LEARNING_RATE, weight_decay=WEIGHT_DECAY)
    batches = max(1, y.numel() // BATCH)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, MAX_LEARNING_RATE,
                                                total_steps=EPOCHS * batches)  # fmt: skip
    t0 = time.monotonic()
    for epoch in range(EPOCHS):
        order = torch.randperm(y.numel())
        for b in range(batches):
            idx = order[b * BATCH : (b + 1) * BATCH]
            loss = nn.functional.cross_entropy(net(x[idx], s[idx]), y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
        say(f"shape network: epoch {epoch + 1}/{EPOCHS}, last batch's loss {loss.item():.3f}, "
            f"{time.monotonic() - t0:.0f} s")  # fmt: skip
    return export_shape_net(net, mu, sd, s.amin(0), s.amax(0))


def shape_module(nn: Any, mu: Any, sd: Any) -> Any:
    """The network of ``signal_shape`` as a torch module (built here: torch is imported
    only when fitting)."""
    import torch

    class Net(nn.Module):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self.convs = nn.ModuleList(
                nn.Conv1d(CHANNELS[i], CHANNELS[i + 1], k, stride=2, padding=k // 2)
                for i, k in enumerate(KERNELS)
            )
            self.bns = nn.ModuleList(nn.BatchNorm1d(c) for c in CHANNELS[1:])
            self.fc1 = nn.Linear(2 * CHANNELS[-1] + len(SCALARS), HIDDEN)
            self.fc2 = nn.Linear(HIDDEN, len(CLASSES))

        def forward(self, x: Any, sc: Any) -> Any:
            for conv, bn in zip(self.convs, self.bns, strict=True):
                x = torch.relu(bn(conv(x)))
            h = torch.cat([x.mean(2), x.amax(2), (sc - mu) / sd], 1)
            return self.fc2(torch.relu(self.fc1(h)))

    return Net()


def export_shape_net(net: Any, mu: Any, sd: Any, lo: Any, hi: Any) -> ShapeNet:
    """The weights as float64 arrays, each batch normalisation folded into its convolution;
    ``mu``, ``sd``, ``lo``, ``hi``: the scalars' mean, spread and range over the fit windows
    (inside it the clip leaves the fit's own inputs as they were)."""
    conv_w, conv_b = [], []
    for conv, bn in zip(net.convs, net.bns, strict=True):
        scale = (bn.weight.double() / (bn.running_var.double() + bn.eps).sqrt()).detach().numpy()
        w = conv.weight.double().detach().numpy()
        b = conv.bias.double().detach().numpy()
        mean = bn.running_mean.double().detach().numpy()
        conv_w.append(w * scale[:, None, None])
        conv_b.append((b - mean) * scale + bn.bias.double().detach().numpy())
    dense = (net.fc1, net.fc2)
    return ShapeNet(
        tuple(conv_w),
        tuple(conv_b),
        tuple(d.weight.double().detach().numpy() for d in dense),
        tuple(d.bias.double().detach().numpy() for d in dense),
        mu.double().numpy(),
        sd.double().numpy(),
        lo.double().numpy(),
        hi.double().numpy(),
    )


def fit_blend(
    log_trees: NDArray[np.float64], log_shape: NDArray[np.float64], y: NDArray[np.int64]
) -> tuple[float, float]:
    """The network's weight (``BLEND_WEIGHTS``) and the blend's temperature that minimise the
    negative log-likelihood of ``y`` on the calibration windows."""
    best = (math.inf, 0.0, 1.0)
    rows = np.arange(y.size)
    for w in BLEND_WEIGHTS:

        def nll(log_t: float, w: float = w) -> float:
            p = blended(log_trees, log_shape, w, math.exp(log_t))
            return float(-np.mean(safe_log(p[rows, y])))

        res = minimize_scalar(nll, bounds=(math.log(0.2), math.log(5.0)), method="bounded")
        if res.fun < best[0]:
            best = (float(res.fun), w, float(math.exp(res.x)))
    return best[1], best[2]
