"""The durable buffer (``storage/buffer.py``): samples leave in the order they came, survive a
restart of the process, and what does not fit is counted, on a real SQLite file."""

from __future__ import annotations

from pathlib import Path

import pytest

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import BAD_NO_COMMUNICATION, GOOD
from plantcheck.storage.buffer import DurableBuffer
from plantcheck.storage.errors import StorageError


def _rows(tag: int, n: int, t0: int = 0) -> list[Sample]:
    return [Sample(tag, t0 + k, t0 + k, float(k), GOOD) for k in range(n)]


def test_first_in_first_out_across_a_restart(tmp_path: Path) -> None:
    buf = DurableBuffer(tmp_path / "b.db", 100)
    buf.append(_rows(1, 3) + _rows(2, 2, 10))
    buf.close()
    again = DurableBuffer(tmp_path / "b.db", 100)  # the service restarted
    assert len(again) == 5
    seq, first = again.peek(3)
    assert [(s.tag_id, s.ts_us) for s in first] == [(1, 0), (1, 1), (1, 2)]
    again.remove_through(seq)
    assert len(again) == 2 and [s.tag_id for s in again.peek(10)[1]] == [2, 2]
    again.close()


def test_what_does_not_fit_is_counted_not_hidden(tmp_path: Path) -> None:
    buf = DurableBuffer(tmp_path / "b.db", 4)
    assert buf.append(_rows(1, 6)) == 2
    assert len(buf) == 4 and buf.dropped == 2
    assert [s.ts_us for s in buf.peek(10)[1]] == [0, 1, 2, 3]  # the oldest kept
    buf.close()


def test_newest_sample_per_tag(tmp_path: Path) -> None:
    buf = DurableBuffer(tmp_path / "b.db", 100)
    buf.append([*_rows(1, 3), Sample(2, 50, 50, None, BAD_NO_COMMUNICATION)])
    assert buf.newest() == {1: (2, GOOD), 2: (50, BAD_NO_COMMUNICATION)}
    buf.close()


def test_an_unwritable_path_names_the_key_to_fix(tmp_path: Path) -> None:
    with pytest.raises(StorageError, match=r"storage\.buffer_path"):
        DurableBuffer(tmp_path / "missing" / "b.db", 100)
