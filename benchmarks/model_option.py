"""The ``--model FILE`` option the accuracy benchmarks share: read another model file than
the shipped one (``plantcheck model fit --out FILE`` writes one); with ``--decision``, the chain
settings that read their windows by the rules or by the learned decision."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from plantcheck.diagnosis import ChainParams
from plantcheck.diagnosis.cause_model import CauseModel, load_cause_model, shipped_cause_model


def chosen_model(path: Path | None, option: str = "--model") -> CauseModel | None:
    """The model in ``path``, or the shipped one (None when the build has none) without it;
    a missing file ends the benchmark with a message naming the option and the fix."""
    if path is None:
        return shipped_cause_model()
    if not path.is_file():
        sys.exit(f"{option} {path}: no such file (plantcheck model fit --out FILE writes one)")
    return load_cause_model(path)


def add_decision_options(ap: argparse.ArgumentParser) -> None:
    """``--decision rules|learned`` (who names the cause, as ``plantcheck diagnose --decision``)
    and ``--model FILE``."""
    ap.add_argument("--decision", choices=("rules", "learned"), default="rules")
    ap.add_argument("--model", type=Path, help="a model file (plantcheck model fit --out)")


def decision_params(args: argparse.Namespace) -> ChainParams:
    """The chain settings of ``add_decision_options``' parsed ``args``."""
    return ChainParams(cause_model=chosen_model(args.model), decide_by=args.decision)


BOTH_DECISIONS = ("rules", "learned")


def corpus_scan(
    ap: argparse.ArgumentParser, windows: int, what: str
) -> tuple[argparse.Namespace, dict[str, ChainParams]]:
    """``--seed`` (default 505), ``--windows`` (``windows``: corpus windows ``what``) and
    ``--model FILE`` for a benchmark that reads corpus windows by both decisions: the parsed
    arguments and each decision's chain settings; a bad count or no model file ends it with
    a message naming the option."""
    ap.add_argument("--seed", type=int, default=505, help="corpus seed (default 505)")
    ap.add_argument(
        "--windows", type=int, default=windows, help=f"corpus windows {what} (default {windows})"
    )
    ap.add_argument("--model", type=Path, help="a model file (plantcheck model fit --out)")
    args = ap.parse_args()
    if args.windows < 1:
        ap.error(f"--windows {args.windows}: give 1 or more")
    model = chosen_model(args.model)
    if model is None:
        ap.error("no model file to read the learned decision from: give --model FILE")
    params = {name: ChainParams(cause_model=model, decide_by=name) for name in BOTH_DECISIONS}
    return args, params
