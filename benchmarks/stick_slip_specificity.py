"""How often the stick-slip detector finds events on healthy loops and on sticky ones: the
corpus' windows by the process' dead time, and issue 24's short-window family.

The learned decision weighs the events as the corpus shows them (issue 46): a detector that
fires on a third of the corpus' healthy windows is evidence the trees learn to discount,
though it fires on a tenth of the short-window family's healthy twins and on nine in ten of
its sticky valves (benchmarks/README.md, *Fiftieth session*). The two-model test that
confirms an event (a *strong* one) tries dead times of 0-8 samples (``stick_slip.DELAY_GRID``)
and the corpus' run to hundreds, so the table splits the corpus' windows by their true dead
time in samples. Every figure is the chain's own evidence (``chain.chain_evidence``: its
``events`` and ``strong_events``), so a change to the detector shows here as the decision
will read it. Windows of calibration seed 202 (the check seed is not read), from 300
samples up (the detector's least); the family's seeds 1-4.

``--delays 0,1,2,4,8,16,32,64`` runs the two-model test's linear model over other dead times
(samples; ``stick_slip.DELAY_GRID`` is replaced for this run): a what-if for the detector, whose
figures then differ from what the shipped decision reads.

    python benchmarks/stick_slip_specificity.py [--windows 3000] [--classes ok stiction ...]
        [--delays 0,1,2,4,8]
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections
import time

import plantcheck.diagnosis.stick_slip as stick_slip
from plantcheck.diagnosis.chain import chain_evidence
from plantcheck.service.cause_model_fit import CALIBRATION_SEED
from plantcheck.simulator.cases import generate_short_window_cases
from plantcheck.simulator.corpus import CLASSES, draw_cases
from plantcheck.simulator.loop import LoopRecord, simulate_loop

GRID_END = float(max(stick_slip.DELAY_GRID))
DEAD_TIME_BANDS = ((0.0, GRID_END), (GRID_END, 4.0 * GRID_END), (4.0 * GRID_END, float("inf")))
"""Dead time bands, samples: the chain's two-model test tries the first (0-8)."""

MIN_SAMPLES = stick_slip.StickSlipParams().min_samples
"""The detector's fewest samples for a verdict."""


def events_of(rec: LoopRecord, ts: float, loop_type: str) -> tuple[bool, bool] | None:
    """Whether the chain's evidence of the record holds an event, and a strong one; None for
    a window with nothing to weigh."""
    _, ev = chain_evidence(rec.pv, rec.op, ts, sp=rec.sp, loop_type=loop_type)
    if ev is None:
        return None
    return (ev.get("events") or 0.0) >= 1.0, (ev.get("strong_events") or 0.0) >= 1.0


def count(row: list[int], found: tuple[bool, bool]) -> None:
    """Add one window to a ``[windows, with events, with strong events]`` row."""
    row[0] += 1
    row[1] += found[0]
    row[2] += found[1]


def positive(text: str) -> int:
    """``--windows``: a whole number from 1 up."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: give a whole number of windows, e.g. 3000")
    return n


def band_of(dead_time_samples: float) -> str:
    """The ``DEAD_TIME_BANDS`` label of a dead time (samples)."""
    for lo, hi in DEAD_TIME_BANDS:
        if lo <= dead_time_samples <= hi:
            return f"{lo:g}-{hi:g}" if hi != float("inf") else f"over {lo:g}"
    raise ValueError(f"dead time {dead_time_samples} samples: not in any band")


def delays_of(text: str) -> tuple[int, ...]:
    """``--delays``: whole samples from 0 up, comma-separated, 0 among them."""
    try:
        delays = tuple(sorted({int(v) for v in text.split(",")}))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give whole samples, e.g. 0,1,2,4,8") from None
    if delays[0] != 0:
        raise argparse.ArgumentTypeError(f"{text!r}: start at 0 (no dead time), e.g. 0,1,2,4,8")
    return delays


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--windows", type=positive, default=3000, help="corpus windows of seed 202 to draw (3000)"
    )
    ap.add_argument(
        "--classes",
        nargs="+",
        default=["ok", "stiction", "sluggish_tuning"],
        choices=CLASSES,
        help="the corpus classes to read",
    )
    ap.add_argument(
        "--delays",
        type=delays_of,
        default=stick_slip.DELAY_GRID,
        help="the two-model test's dead times, samples, comma-separated (default: the chain's)",
    )
    a = ap.parse_args()
    stick_slip.DELAY_GRID = a.delays
    t0 = time.perf_counter()
    # (class, band) -> [windows, with events, with strong events]
    counts: dict[tuple[str, str], list[int]] = collections.defaultdict(lambda: [0, 0, 0])
    indices = [i for i in range(a.windows) if CLASSES[i % len(CLASSES)] in a.classes]
    for case, rec in draw_cases(CALIBRATION_SEED, indices):
        if rec.pv.size < MIN_SAMPLES:
            continue
        cfg = case.config
        found = events_of(rec, cfg.sample_time_s, case.loop_type)
        if found is None:
            continue
        count(counts[(case.cause, band_of(cfg.process.theta_s / cfg.sample_time_s))], found)
    print(f"corpus seed {CALIBRATION_SEED}, windows 0-{a.windows - 1} of {', '.join(a.classes)}, "
          f"from {MIN_SAMPLES} samples up, dead times tried {a.delays}: share with an event, "
          "with a strong one")  # fmt: skip
    print("class".ljust(22) + "dead time (samples)".ljust(22) + "windows  events  strong")
    for (cls, band), (n, ev, strong) in sorted(counts.items()):
        print(f"{cls:22s}{band:22s}{n:7d}  {ev / n:6.2f}  {strong / n:6.2f}")
    family: dict[str, list[int]] = collections.defaultdict(lambda: [0, 0, 0])
    for seed in (1, 2, 3, 4):
        for case in generate_short_window_cases(seed):
            found = events_of(simulate_loop(case.config), case.config.sample_time_s,
                              case.loop_type)  # fmt: skip
            if found is not None:
                count(family[case.cause], found)
    print("short-window family, seeds 1-4:")
    for cls, (n, ev, strong) in sorted(family.items()):
        print(f"{cls:22s}{'':22s}{n:7d}  {ev / n:6.2f}  {strong / n:6.2f}")
    print(f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
