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
