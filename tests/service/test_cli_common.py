"""Durations as operators write them (``service/cli_common.parse_duration``) and the worker's
automatic-mode mask (``service/window_diagnosis.automatic``)."""

from __future__ import annotations

import numpy as np
import pytest

from plantcheck.service.cli_common import parse_duration
from plantcheck.service.window_diagnosis import automatic


@pytest.mark.parametrize(
    ("text", "seconds"),
    [("90", 90.0), ("90s", 90.0), ("15m", 900.0), ("2h", 7200.0), ("1d", 86400.0),
     ("1h30m", 5400.0), ("10min", 600.0), ("1.5h", 5400.0)],
)  # fmt: skip
def test_durations(text: str, seconds: float) -> None:
    assert parse_duration(text) == seconds


@pytest.mark.parametrize("text", ["", "h", "2x", "1h-30m", "ten minutes"])
def test_a_bad_duration_says_how_to_write_one(text: str) -> None:
    with pytest.raises(ValueError, match=r"use e\.g\. 3600, 90s, 15m, 2h or 1d"):
        parse_duration(text)


def test_unknown_mode_counts_as_automatic() -> None:
    assert automatic(None) is None
    assert automatic(np.full(3, np.nan)) is None
    mask = automatic(np.array([1.0, 0.0, np.nan, 1.0]))
    assert mask is not None and mask.tolist() == [True, False, True, True]
