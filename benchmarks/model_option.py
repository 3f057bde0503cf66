"""The ``--model FILE`` option the accuracy benchmarks share: read another model file than
the shipped one (``plantcheck model fit --out FILE`` writes one)."""

from __future__ import annotations

import sys
from pathlib import Path

from plantcheck.diagnosis.cause_model import CauseModel, load_cause_model, shipped_cause_model


def chosen_model(path: Path | None, option: str = "--model") -> CauseModel | None:
    """The model in ``path``, or the shipped one (None when the build has none) without it;
    a missing file ends the benchmark with a message naming the option and the fix."""
    if path is None:
        return shipped_cause_model()
    if not path.is_file():
        sys.exit(f"{option} {path}: no such file (plantcheck model fit --out FILE writes one)")
    return load_cause_model(path)
