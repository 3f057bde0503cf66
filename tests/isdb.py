"""Loader for the ISDB loops in ../shared/data/isdb-partial-npokhappy (not copied into the repo)."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

SHARED = Path(__file__).resolve().parents[2] / "shared"
ISDB_DIR = SHARED / "data" / "isdb-partial-npokhappy"

# Labels accepted as right answers for each ISDB comment label (standard chain, no MV).
ACCEPTED: dict[str, frozenset[str]] = {
    "stiction": frozenset({"stiction"}),
    "stiction_likely": frozenset({"stiction"}),
    "external_disturbance": frozenset({"external_disturbance"}),
    # dead zone + tight tuning: a valve nonlinearity and an aggressive controller; both are right
    "deadzone+tight_tuning": frozenset({"stiction", "aggressive_tuning"}),
    # "no stiction" does not mean healthy (data README): anything but stiction is right
    "no_stiction": frozenset(
        {
            "ok",
            "aggressive_tuning",
            "sluggish_tuning",
            "external_disturbance",
            "oscillation_unknown_cause",
            "saturation",
        }
    ),
}


@dataclass(frozen=True)
class IsdbLoop:
    """One ISDB loop: name, comment label, sample time (s), loop type, OP and PV."""

    name: str
    label: str
    ts: float
    loop_type: str
    description: str
    op: NDArray[np.float64]
    pv: NDArray[np.float64]


def loop_type_of(description: str) -> str:
    d = description.lower()
    if d.startswith("flow"):
        return "flow"
    if d.startswith("pressure"):
        return "pressure"
    if d.startswith("temperature"):
        return "temperature"
    if d.startswith("level"):
        return "level"
    if d.startswith(("analyser", "concentration")):
        return "composition"
    return "other"


@cache
def _column(path: Path) -> NDArray[np.float64]:
    return np.loadtxt(path, dtype=np.float64)


def load_isdb() -> list[IsdbLoop]:
    """All loops of loop_index.csv; empty list when the shared data is absent."""
    index = ISDB_DIR / "loop_index.csv"
    if not index.exists():
        return []
    loops = []
    with index.open(newline="") as f:
        for row in csv.DictReader(f):
            start, n = int(row["start_row"]), int(row["n_rows"])
            op = _column(ISDB_DIR / row["file_op"])[start : start + n]
            pv = _column(ISDB_DIR / row["file_pv"])[start : start + n]
            loops.append(
                IsdbLoop(
                    row["isdb_loop"],
                    row["label_from_comment"],
                    float(row["ts_s"]),
                    loop_type_of(row["short_description"]),
                    row["short_description"],
                    op,
                    pv,
                )
            )
    return loops
