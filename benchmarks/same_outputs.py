"""Does a change leave the diagnosis's outputs the same, bit for bit, on generated windows?

For speed work that must not move any figure: run it once with the code before the change
(writing its outputs), once with the code after (comparing with them). Per window of corpus
``--seed`` (the corpus the learned decision is fitted and checked on, every family): the
rules' cause and every evidence value (``chain_evidence``), the whole JSON of ``diagnose`` (with
the S/J estimate on every tenth window) and of ``diagnose_advanced`` on every fourth. Floats are
compared by their ``repr``: any changed bit is a difference. Prints the differences (the first
few in full) and exits 1 when there are any.

    python benchmarks/same_outputs.py --write /tmp/before.json      # in the code before
    python benchmarks/same_outputs.py --against /tmp/before.json    # in the code after

The code before can be a worktree put first on the path: ``git worktree add /tmp/old REV;
mkdir /tmp/oldpkg; ln -s /tmp/old /tmp/oldpkg/plantcheck; PYTHONPATH=/tmp/oldpkg python
benchmarks/same_outputs.py --write ...`` (run from outside the checkout). 2,000 windows take
about a minute on two cores.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

Outputs = dict[int, dict[str, str]]
"""Per window index: each output's ``repr`` (evidence) or sorted JSON (diagnoses)."""


def window_outputs(args: tuple[int, int]) -> tuple[int, dict[str, str]]:
    """The outputs of window ``index`` of corpus ``seed``."""
    from plantcheck.diagnosis.chain import chain_evidence, diagnose, diagnose_advanced
    from plantcheck.simulator.corpus import draw_case

    seed, index = args
    case, rec = draw_case(seed, index)
    ts, kind = case.config.sample_time_s, case.loop_type
    out = {"evidence": repr(chain_evidence(rec.pv, rec.op, ts, sp=rec.sp, loop_type=kind))}
    d = diagnose(rec.pv, rec.op, ts, sp=rec.sp, loop_type=kind, quantify=index % 10 == 0)
    out["standard"] = json.dumps(d.to_dict(), sort_keys=True, default=str)
    if index % 4 == 0:
        a = diagnose_advanced(rec.pv, rec.op, rec.mv, ts, sp=rec.sp, loop_type=kind, quantify=False)
        out["advanced"] = json.dumps(a.to_dict(), sort_keys=True, default=str)
    return index, out


def all_outputs(seed: int, windows: int, jobs: int) -> Outputs:
    """Every window's outputs, on ``jobs`` processes."""
    ctx = multiprocessing.get_context("fork" if sys.platform != "darwin" else "spawn")
    with ctx.Pool(jobs) as pool:
        return dict(pool.imap(window_outputs, [(seed, i) for i in range(windows)], chunksize=8))


def differences(before: Outputs, after: Outputs) -> list[tuple[int, str, str, str]]:
    """(window, output, before, after) wherever the two differ or one lacks the output."""
    diffs = []
    for i in sorted(set(before) | set(after)):
        b, a = before.get(i, {}), after.get(i, {})
        for key in sorted(set(b) | set(a)):
            if b.get(key) != a.get(key):
                diffs.append((i, key, b.get(key, "(none)"), a.get(key, "(none)")))
    return diffs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--write", type=Path, help="write this code's outputs to the file")
    what.add_argument("--against", type=Path, help="compare this code's outputs with the file")
    ap.add_argument("--seed", type=int, default=202, help="corpus seed (default 202)")
    ap.add_argument("--windows", type=int, default=2000)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    if args.against is not None:
        saved = json.loads(args.against.read_text(encoding="utf-8"))
        seed, windows = saved["seed"], saved["windows"]
        before = {int(i): out for i, out in saved["outputs"].items()}
    else:
        seed, windows = args.seed, args.windows
    outputs = all_outputs(seed, windows, args.jobs)
    if args.write is not None:
        saved = {"seed": seed, "windows": windows, "outputs": outputs}
        args.write.write_text(json.dumps(saved), encoding="utf-8")
        print(f"wrote the outputs of {windows} windows of corpus seed {seed} to {args.write}")
        return 0
    diffs = differences(before, outputs)
    for i, key, b, a in diffs[:5]:
        # from a little before the first character that differs
        at = next((k for k, (x, y) in enumerate(zip(b, a, strict=False)) if x != y), 0)
        lo = max(0, at - 80)
        print(f"window {i}, {key}:\n  before ...{b[lo : at + 200]}\n  after  ...{a[lo : at + 200]}")
    print(f"{windows} windows of corpus seed {seed}: {len(diffs)} outputs differ")
    return 1 if diffs else 0


if __name__ == "__main__":
    raise SystemExit(main())
