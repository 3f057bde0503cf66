"""Loops an operator held in manual for a while, or whose transmitter froze: corpus windows
drawn again with such a stretch, read by the rules and by the learned decision (issue 46
items 1 and 7).

The corpus draws every window in automatic with a live transmitter. Plants do not: loops go
to manual for hours, most historians keep no mode tag, and a failed measurement is held at
its last value by the DCS (Thornhill & Horch 2007 list both among the faults that pass for a
loop's). The window checks read an unflagged manual stretch from OP held bit for bit under a
live PV (``diagnosis.window.held_output``) and a frozen transmitter from a PV held while OP
ramps on a straight line (``frozen_pv``); neither decision was fitted on either.

Every window of corpus ``--seed`` among its first ``--windows`` is simulated again, the rest
as drawn, with one stretch at a random place:

- ``manual, short``: the loop in manual for 2-9 % of the window (``LoopConfig.manual``),
  with the mode flag given to the chain (``flag``) or not (``no flag``, as most historians
  keep it): the window is judged, its manual time left out (methods §1.2), so the true
  cause is the right answer;
- ``manual, long``: in manual for 15-40 %: less than the 90 % automatic time methods §1.2
  asks, so ``manual_mode`` is right;
- ``frozen, short``: the transmitter frozen for 1-4 % (``LoopConfig.frozen_pv``), bridged as
  missing samples: the true cause is right;
- ``frozen, long``: frozen for 10-30 %, more than a window bridges: ``data_quality`` is
  right, and the note should name the transmitter.

Prints, per variant and decision, the share read right, the window verdicts
(``manual_mode``, ``data_quality``, ``insufficient_data``), how many windows the checks
named the stretch in (the notes of ``diagnosis.window._held`` and ``_frozen``; ``-`` where
the flag told them; on the windows as drawn, a stretch named where none was drawn), the
other causes; then the right share per class.

    python benchmarks/held_and_frozen_accuracy.py [--seed 505] [--windows 600] [--model FILE]
"""

from __future__ import annotations

# ruff: noqa: E402 (one BLAS thread is asked for before numpy loads, below the first imports)
from plantcheck.service.blas_threads import one_blas_thread

one_blas_thread()  # before numpy loads, as the CLI does: a diagnosis' last digits depend on it

import argparse
import collections
import time
from dataclasses import dataclass, replace

import numpy as np
from model_option import BOTH_DECISIONS as DECISIONS
from model_option import corpus_scan

from plantcheck.diagnosis import ChainParams, diagnose
from plantcheck.simulator.corpus import CLASSES, CorpusCase, draw_cases
from plantcheck.simulator.loop import LoopConfig, LoopRecord, manual_mask, simulate_loop

WINDOW_VERDICTS = ("manual_mode", "data_quality", "insufficient_data")


@dataclass(frozen=True)
class Variant:
    """A stretch drawn into a window: its ``kind`` (``manual`` or ``frozen_pv``; none for
    the window as drawn), its share of the window (drawn uniformly between ``share``'s
    bounds), whether the chain is told of it (the mode flag), and the right answer
    (``expect``; None: the window's true cause)."""

    name: str
    kind: str = ""
    share: tuple[float, float] = (0.0, 0.0)
    flagged: bool = False
    expect: str | None = None


VARIANTS = (
    Variant("as drawn"),
    Variant("manual, short, flag", "manual", (0.02, 0.09), flagged=True),
    Variant("manual, short, no flag", "manual", (0.02, 0.09)),
    Variant("manual, long, flag", "manual", (0.15, 0.4), flagged=True, expect="manual_mode"),
    Variant("manual, long, no flag", "manual", (0.15, 0.4), expect="manual_mode"),
    Variant("frozen, short", "frozen_pv", (0.01, 0.04)),
    Variant("frozen, long", "frozen_pv", (0.1, 0.3), expect="data_quality"),
)
NAMED = {"manual": "OP held exactly still", "frozen_pv": "PV repeated its value bit for bit"}
"""How the window checks' notes begin where they found a stretch of each kind."""


def stretched(cfg: LoopConfig, variant: Variant, rng: np.random.Generator) -> LoopConfig:
    """``cfg`` with one stretch of ``variant`` at a random place in the record."""
    duration = cfg.n_samples * cfg.sample_time_s
    length = duration * float(rng.uniform(*variant.share))
    start = float(rng.uniform(0.0, duration - length))
    return replace(cfg, **{variant.kind: ((start, start + length),)})


def sought(v: Variant) -> list[str]:
    """How the notes begin where the checks found ``v``'s stretch: nothing to find where the
    flag told them; on the window as drawn, either kind (a stretch found where none is)."""
    if not v.kind:
        return list(NAMED.values())
    return [] if v.flagged else [NAMED[v.kind]]


@dataclass(frozen=True)
class Reading:
    """One window under one variant: each decision's cause, and whether the checks found
    the stretch."""

    causes: dict[str, str]
    found: bool


def read_window(
    case: CorpusCase, drawn: LoopRecord, seed: int, params: dict[str, ChainParams]
) -> dict[str, Reading]:
    """Per variant, the window's reading; ``drawn``, its record as the corpus drew it."""
    rng = np.random.default_rng([seed, case.index])
    out: dict[str, Reading] = {}
    for variant in VARIANTS:
        cfg, rec = case.config, drawn
        if variant.kind:
            cfg = stretched(case.config, variant, rng)
            rec = simulate_loop(cfg)
        auto = ~manual_mask(cfg) if variant.flagged else None
        causes: dict[str, str] = {}
        found = False
        look_for = sought(variant)
        for name, p in params.items():
            d = diagnose(rec.pv, rec.op, cfg.sample_time_s, sp=rec.sp, auto=auto,
                         loop_type=case.loop_type, params=p, quantify=False)  # fmt: skip
            causes[name] = d.cause
            found = found or any(n.startswith(b) for n in d.notes for b in look_for)
        out[variant.name] = Reading(causes, found)
    return out


Counts = dict[tuple[str, str], collections.Counter[str]]


def table(counts: Counts, found: collections.Counter[str], windows: int) -> None:
    """The shares per variant and decision, and per class."""
    print(f"{'variant':22} {'decision':8} {'right':>6} {'manual':>6} {'d_qual':>6} "
          f"{'insuff':>6} {'found':>6}  other causes")  # fmt: skip
    for v in VARIANTS:
        for name in DECISIONS:
            c = counts[(v.name, name)]
            right = sum(n for k, n in c.items() if k.startswith("right:"))
            rest = collections.Counter(
                {k.split(":")[1]: n for k, n in c.items() if k.startswith("wrong:")}
            )
            other = ", ".join(f"{k} {n}" for k, n in rest.most_common(4)
                              if k not in WINDOW_VERDICTS)  # fmt: skip
            verdicts = (c[f"said:{k}"] for k in WINDOW_VERDICTS)
            share = [100.0 * x / windows for x in (right, *verdicts)]
            seen = f"{100.0 * found[v.name] / windows:5.1f}%" if not v.flagged else "     -"
            print(f"{v.name:22} {name:8} " + " ".join(f"{s:5.1f}%" for s in share)
                  + f" {seen}  {other}")  # fmt: skip
    print("\nthe true cause's share per class (learned decision):")
    print(f"{'variant':22} " + " ".join(f"{k[:10]:>10}" for k in CLASSES))
    for v in VARIANTS:
        c = counts[(v.name, "learned")]
        cells = []
        for k in CLASSES:
            n = c[f"right:{k}"] + c[f"of:{k}"]
            cells.append(f"{100.0 * c[f'right:{k}'] / n:9.1f}%" if n else f"{'-':>10}")
        print(f"{v.name:22} " + " ".join(cells))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    args, params = corpus_scan(ap, 600, "read")
    counts: Counts = collections.defaultdict(collections.Counter)
    found: collections.Counter[str] = collections.Counter()
    t0 = time.perf_counter()
    read = 0
    for case, drawn in draw_cases(args.seed, range(args.windows)):
        readings = read_window(case, drawn, args.seed, params)
        for variant in VARIANTS:
            reading = readings[variant.name]
            found[variant.name] += reading.found
            for name, cause in reading.causes.items():
                c = counts[(variant.name, name)]
                c[f"said:{cause}"] += 1
                if cause == (variant.expect or case.cause):
                    c[f"right:{case.cause}"] += 1
                else:
                    c[f"wrong:{cause}"] += 1
                    c[f"of:{case.cause}"] += 1
        read += 1
        if read % 50 == 0:
            print(f"  {read} windows read, {time.perf_counter() - t0:.0f} s", flush=True)
    print(f"corpus seed {args.seed}, windows 0-{args.windows - 1}: {read} windows, each as "
          f"drawn and under six stretches ({time.perf_counter() - t0:.0f} s)")  # fmt: skip
    table(counts, found, read)


if __name__ == "__main__":
    main()
