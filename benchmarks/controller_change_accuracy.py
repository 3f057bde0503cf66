"""How often the controller-change search (``diagnosis.controller_change``, issue 48) finds a
retuning that never happened, and how often it finds one that did, on the corpus' loops.

A window in which the search finds a retuning is judged from it on, with a note saying the
controller was retuned: a change found in a loop nobody touched throws away the window's start
and tells the engineer something false. The corpus (``simulator/corpus.py``) holds every
process, valve, load, set-point pattern, output limit and historian recording the learned
decision is fitted on, and no retuning: each of its windows of at least ``MIN_SAMPLES``
samples is simulated as drawn (a change found there is false) and again with the PI settings
typed in at the window's middle (Kc and Ti each kept, halved or doubled, not both kept; the
integral state carries OP over, as a DCS does: ``ClosedLoop.set_controller``), recorded by the
same historian. Prints per recording, per set-point pattern and per class the windows, the
false changes, and the retunings found within ``PLACED`` of the window's length of where they
were made, found elsewhere, or missed.

    python benchmarks/controller_change_accuracy.py [--seed 202] [--windows 1200]
        [--first 0] [--jobs 2]
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()

import argparse
import collections
import multiprocessing
import os
import sys
import time
from dataclasses import dataclass

import numpy as np

from plantcheck.diagnosis.chain import default_chain_params
from plantcheck.diagnosis.controller_change import latest_controller_change
from plantcheck.simulator.corpus import draw_case
from plantcheck.simulator.loop import simulate_retuned_loop

MIN_SAMPLES = 1000
"""Windows shorter than this are left out: the search wants 200 samples a side, and a
retuning at the middle of a shorter window leaves a side too short to judge."""

PLACED = 0.05
"""A retuning found within this share of the window's length of where it was made counts as
found; farther, as found elsewhere."""

RETUNINGS = ((0.5, 1.0), (2.0, 1.0), (1.0, 0.5), (1.0, 2.0), (0.5, 2.0), (2.0, 0.5))
"""(Kc, Ti) factors of the retuning: one is drawn per window."""


@dataclass(frozen=True)
class Row:
    """One window: its label and what the search found with and without the retuning."""

    index: int
    cause: str
    family: dict[str, str]
    samples: int
    false_at: int | None
    """Where a change was found in the window as drawn (None: none)."""
    found_at: int | None
    """Where the last change was found in the retuned window (None: none)."""
    made_at: int


def one_window(args: tuple[int, int]) -> Row | None:
    seed, index = args
    case, drawn = draw_case(seed, index)
    cfg = case.config
    n = cfg.n_samples
    if n < MIN_SAMPLES:
        return None
    p = default_chain_params().controller_change
    ts = cfg.sample_time_s
    factors = RETUNINGS[int(np.random.default_rng([seed, index, 48]).integers(len(RETUNINGS)))]
    made = n // 2
    found: list[int | None] = []
    c = cfg.controller
    retuned = (c.Kc * factors[0], c.Ti_s * factors[1])
    for rec in (drawn, simulate_retuned_loop(cfg, made, *retuned)):
        change = latest_controller_change(rec.pv, rec.op, rec.sp, ts, None, p)
        found.append(None if change is None else change.at)
    return Row(index, case.cause, case.family, n, found[0], found[1], made)


def table(rows: list[Row], key: str) -> None:
    groups: dict[str, list[Row]] = collections.defaultdict(list)
    for r in rows:
        groups[r.cause if key == "class" else r.family[key]].append(r)
    print(f"{key:>22}  windows  false  found  elsewhere  missed")
    for name in [*sorted(groups), "all"]:
        g = rows if name == "all" else groups[name]
        false = sum(r.false_at is not None for r in g)
        found = sum(
            r.found_at is not None and abs(r.found_at - r.made_at) <= PLACED * r.samples for r in g
        )
        missed = sum(r.found_at is None for r in g)
        print(f"{name:>22}  {len(g):7d}  {false:5d}  {found:5d}  {len(g) - found - missed:9d}  "
              f"{missed:6d}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=202, help="corpus seed (default 202)")
    ap.add_argument("--windows", type=int, default=1200, help="corpus windows read (1200)")
    ap.add_argument("--first", type=int, default=0, help="first window index (0)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    for name in ("windows", "jobs"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be at least 1 (got {getattr(args, name)})")
    if args.first < 0:
        ap.error(f"--first must be 0 or more (got {args.first})")
    t0 = time.perf_counter()
    work = [(args.seed, i) for i in range(args.first, args.first + args.windows)]
    with multiprocessing.Pool(args.jobs) as pool:
        rows = []
        for k, row in enumerate(pool.imap(one_window, work, chunksize=8), 1):
            if row is not None:
                rows.append(row)
            if k % 200 == 0:
                print(f"  {k} of {len(work)} windows", file=sys.stderr, flush=True)
    last = args.first + args.windows - 1
    took = time.perf_counter() - t0
    print(f"corpus seed {args.seed}, windows {args.first}-{last}: {len(rows)} of at least "
          f"{MIN_SAMPLES} samples ({took:.0f} s)")  # fmt: skip
    for key in ("recording", "sp", "limit", "class"):
        table(rows, key)
    false = [r for r in rows if r.false_at is not None]
    print(f"all: {len(false)} false changes in {len(rows)} windows")
    for r in false[:12]:
        print(f"  window {r.index} {r.cause} ({r.samples} samples) at {r.false_at}: {r.family}")


if __name__ == "__main__":
    main()
