"""How fast the training corpus is drawn (issue 46): windows a second of shapes and of evidence
on ``--jobs`` processes, and what the batch simulator's cost model reads
(``simulator.batch_loop``: a batch's sample, each loop's sample, a sticky model's, and
``simulate_loop``'s sample, all with their inputs and records).

Nothing is cached: every window is simulated again. ``both``: the evidence and the shapes
of each window simulated once, as ``model fit`` reads them. ``--seed`` chooses the windows (fit seed
101 by default, from window 0); the figures of two versions of the code are comparable only
on the same windows, alternated, as this machine's speed drifts.

    python benchmarks/corpus_speed.py [--windows 4000] [--jobs 2] [--skip-evidence] [--costs]
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as `model fit` does: the evidence depends on it

import numpy as np  # noqa: E402

from plantcheck.service.cause_model_fit import (  # noqa: E402
    corpus_evidence,
    corpus_evidence_and_shapes,
)
from plantcheck.service.shape_model_fit import corpus_shapes  # noqa: E402
from plantcheck.simulator.batch_loop import _batch  # noqa: E402
from plantcheck.simulator.corpus import CLASSES, _draw  # noqa: E402
from plantcheck.simulator.loop import LoopConfig, simulate_loop  # noqa: E402


def _rates(seed: int, windows: int, jobs: int, evidence: bool) -> None:
    draws: list[tuple[str, Callable[..., object]]] = [("shapes", corpus_shapes)]
    if evidence:
        # the two one after the other, then both of each window simulated once (`model fit`)
        draws += [("evidence", corpus_evidence), ("both", corpus_evidence_and_shapes)]
    for name, draw in draws:
        t0 = time.perf_counter()
        draw(seed, windows, jobs=jobs)
        dt = time.perf_counter() - t0
        print(f"{name + ':':9s} {windows} windows of seed {seed} in {dt:.1f} s: "
              f"{windows / dt:.1f} a second", flush=True)  # fmt: skip


def _first_draws(seed: int, count: int) -> tuple[list[LoopConfig], list[LoopConfig]]:
    """First draws of corpus windows: ``count`` with a sound valve and ``count`` sticky."""
    sound: list[LoopConfig] = []
    sticky: list[LoopConfig] = []
    index = 0
    while len(sticky) < count or len(sound) < count:
        case = _draw(np.random.default_rng([seed, index, 0]), index, CLASSES[index % 6])
        index += 1
        (sticky if case.config.valve != "linear" else sound).append(case.config)
    return sound[:count], sticky[:count]


def _costs(seed: int) -> None:
    """Each group alone and in batches of two sizes: a batch's cost per sample is
    ``c0 + active · c1`` (active: loops not yet ended, on average)."""
    sound, sticky = _first_draws(seed, 240)
    for name, group in (("sound valves", sound), ("sticky valves", sticky)):
        lengths = [c.n_samples + c.warmup_samples for c in group]
        t0 = time.perf_counter()
        for c in group[:60]:
            simulate_loop(c)
        alone = (time.perf_counter() - t0) / sum(lengths[:60])
        print(f"{name}: simulate_loop {alone * 1e6:.2f} µs a sample")
        points = []
        for size in (60, 240):
            part = group[:size]
            t0 = time.perf_counter()
            _batch(part)
            dt = time.perf_counter() - t0
            longest = max(c.n_samples + c.warmup_samples for c in part)
            active = sum(c.n_samples + c.warmup_samples for c in part) / longest
            points.append((active, dt / longest))
            print(f"  batch of {size}: {dt / longest * 1e6:.0f} µs a sample, {active:.0f} loops"
                  f" active on average")  # fmt: skip
        (a1, s1), (a2, s2) = points
        c1 = (s2 - s1) / (a2 - a1)
        c0 = s1 - a1 * c1
        print(f"  c0 {c0 * 1e6:.0f} µs, c1 {c1 * 1e6:.2f} µs: STEP_COST {c0 / alone:.1f},"
              f" LOOP_SAMPLE_COST {c1 / alone:.3f} samples of simulate_loop")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=4000)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--seed", type=int, default=101)
    ap.add_argument("--skip-evidence", action="store_true")
    ap.add_argument("--costs", action="store_true", help="also the cost model's constants")
    args = ap.parse_args()
    _rates(args.seed, args.windows, args.jobs, not args.skip_evidence)
    if args.costs:
        _costs(args.seed)


if __name__ == "__main__":
    main()
