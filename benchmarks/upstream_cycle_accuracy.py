"""Loops disturbed by another loop's limit cycle: the corpus' periodic loads as square and
triangular waves instead of sines, read by the rules and by the learned decision (issue 46).

The corpus draws a disturbance from outside as a sine, or a sine and its third harmonic
(``simulator.corpus._periodic_load``). In a plant the commonest periodic load is another
loop's limit cycle (Thornhill & Horch 2007): a sticky valve or an on/off unit upstream jumps
between two positions, so the load is a square wave with lagged edges, or a triangle where a
level or an integral action between integrates it. The shape-based stiction tests read a
square loop's PV and OP as a sticky valve's (Horch 1999 warns of it), and neither decision was
fitted on such loads.

Every external-disturbance window of corpus ``--seed`` among its first ``--windows`` is
simulated again with its periodic loads replaced by one of the same period and swing:
``sine`` (as drawn, the reference), ``square`` (high for 30-70 % of each period, edges
through a lag of 1-15 % of the period) and ``triangle`` (rising for 30-70 %, the same lag),
the rest of the window as drawn. A window whose control error does not rise by
``corpus.VISIBLY_FAULTY`` over its twin's (the loop without the periodic load) is counted
as hidden and not read, as the corpus draws again. Prints, per shape and decision, how many
read ``external_disturbance``, how many ``stiction`` (a false alarm: every valve is linear),
and the other causes.

    python benchmarks/upstream_cycle_accuracy.py [--seed 505] [--windows 1200] [--model FILE]
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections
import math
import time
from dataclasses import replace

import numpy as np
from model_option import BOTH_DECISIONS as DECISIONS
from model_option import corpus_scan

from plantcheck.diagnosis import ChainParams, diagnose
from plantcheck.simulator.corpus import (
    LIMIT_CYCLE_DUTY,
    LIMIT_CYCLE_EDGE_LAG,
    VISIBLY_FAULTY,
    CorpusCase,
    draw_cases,
    fault_and_twin,
)
from plantcheck.simulator.loop import Disturbance, LoopConfig, LoopRecord, simulate_loop

SHAPES = ("sine", "square", "triangle")


def reshaped(cfg: LoopConfig, shape: str, rng: np.random.Generator) -> LoopConfig:
    """``cfg`` with its periodic loads (those with a sine amplitude) replaced by one load of
    ``shape``, the first one's period, swing (trough to peak) and entry point; ``sine`` keeps
    drawn sines as they are (a third harmonic where drawn) and makes a drawn limit cycle a
    sine."""
    periodic = [d for d in cfg.disturbances if d.sine_amplitude]
    others = tuple(d for d in cfg.disturbances if not d.sine_amplitude)
    if not periodic or (shape == "sine" and periodic[0].shape == "sine"):
        return cfg
    first = periodic[0]
    if shape == "sine":
        return replace(cfg, disturbances=(replace(first, shape="sine"), *others))
    lag = first.sine_period_s * math.exp(rng.uniform(*np.log(LIMIT_CYCLE_EDGE_LAG)))
    wave = Disturbance(
        where=first.where,
        sine_amplitude=first.sine_amplitude,
        sine_period_s=first.sine_period_s,
        shape=shape,  # type: ignore[arg-type]
        duty=float(rng.uniform(*LIMIT_CYCLE_DUTY)),
        edge_lag_s=lag,
    )
    return replace(cfg, disturbances=(wave, *others))


def read_window(
    case: CorpusCase, drawn: LoopRecord, seed: int, params: dict[str, ChainParams]
) -> dict[str, dict[str, str] | None]:
    """Per shape, each decision's cause of the window under that load (None: hidden);
    ``drawn``, the window's record as the corpus drew it, read where the load stays."""
    assert case.twin is not None
    twin = simulate_loop(case.twin)
    rng = np.random.default_rng([seed, case.index])
    out: dict[str, dict[str, str] | None] = {}
    for shape in SHAPES:
        cfg = reshaped(case.config, shape, rng)
        rec = drawn if cfg is case.config else simulate_loop(cfg)
        shown = fault_and_twin(replace(case, config=cfg), rec, twin)
        if shown is not None and shown[0] < VISIBLY_FAULTY * shown[1]:
            out[shape] = None
            continue
        ts = cfg.sample_time_s
        out[shape] = {
            name: diagnose(rec.pv, rec.op, ts, sp=rec.sp, loop_type=case.loop_type,
                           params=p, quantify=False).cause
            for name, p in params.items()
        }  # fmt: skip
    return out


def table(
    counts: dict[tuple[str, str], collections.Counter[str]], hidden: collections.Counter[str]
) -> None:
    print(f"{'shape':9} {'decision':8} {'windows':>7} {'hidden':>6} {'external':>8} "
          f"{'stiction':>8}  other causes")  # fmt: skip
    for shape in SHAPES:
        for name in DECISIONS:
            c = counts[(shape, name)]
            n = sum(c.values())
            rest = ", ".join(f"{k} {v}" for k, v in c.most_common()
                             if k not in ("external_disturbance", "stiction"))  # fmt: skip
            print(f"{shape:9} {name:8} {n:7d} {hidden[shape]:6d} "
                  f"{c['external_disturbance']:8d} {c['stiction']:8d}  {rest}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    args, params = corpus_scan(ap, 1200, "scanned")
    counts: dict[tuple[str, str], collections.Counter[str]] = collections.defaultdict(
        collections.Counter
    )
    hidden: collections.Counter[str] = collections.Counter()
    t0 = time.perf_counter()
    read = 0
    for case, drawn in draw_cases(args.seed, range(args.windows)):
        if case.cause != "external_disturbance":
            continue
        for shape, causes in read_window(case, drawn, args.seed, params).items():
            if causes is None:
                hidden[shape] += 1
                continue
            for name, cause in causes.items():
                counts[(shape, name)][cause] += 1
        read += 1
        if read % 50 == 0:
            print(f"  {read} windows read, {time.perf_counter() - t0:.0f} s", flush=True)
    print(f"corpus seed {args.seed}, windows 0-{args.windows - 1}: {read} external-disturbance "
          f"windows, each under three load shapes ({time.perf_counter() - t0:.0f} s)")  # fmt: skip
    table(counts, hidden)


if __name__ == "__main__":
    main()
