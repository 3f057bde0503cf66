"""A cached corpus file of fewer windows starts a longer one (``service.corpus_cache``): what
is read from it plus what is drawn after it equals the longer corpus drawn at once. Windows are
read by worker processes in index order, with progress while they are drawn
(``service.corpus_draw``)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from plantcheck.service.cause_model_fit import corpus_evidence, corpus_evidence_and_shapes
from plantcheck.service.corpus_draw import read_windows
from plantcheck.service.shape_model_fit import corpus_shapes
from plantcheck.simulator.corpus import CorpusCase, draw_case
from plantcheck.simulator.loop import LoopRecord


def _only(folder: Path, stem: str) -> Path:
    (path,) = folder.glob(f"{stem}*.npz")
    return path


def test_more_shapes_draw_only_the_windows_beyond_the_cached_ones(tmp_path: Path) -> None:
    whole = corpus_shapes(303, 10, jobs=1)
    head = corpus_shapes(303, 4, jobs=1, cache=tmp_path)
    head.channels[:] = 0  # what is read from the cache, not drawn again, shows as zeros
    np.savez_compressed(_only(tmp_path, "shapes-"), channels=head.channels,
                        scalars=head.scalars, y=head.y, judged=head.judged)  # fmt: skip
    grown = corpus_shapes(303, 10, jobs=1, cache=tmp_path)
    assert not grown.channels[:4].any()
    np.testing.assert_array_equal(grown.channels[4:], whole.channels[4:])
    for got, want in zip((grown.scalars, grown.y, grown.judged),
                         (whole.scalars, whole.y, whole.judged), strict=True):  # fmt: skip
        np.testing.assert_array_equal(got, want)
    assert len(list(tmp_path.glob("shapes-*-10.npz"))) == 1


def test_more_evidence_draws_only_the_windows_beyond_the_cached_ones(tmp_path: Path) -> None:
    whole = corpus_evidence(303, 14, jobs=1)
    corpus_evidence(303, 6, jobs=1, cache=tmp_path)
    path = _only(tmp_path, "corpus-")
    with np.load(path) as z:
        saved = dict(z)
    rows = saved["x"].shape[0]
    assert 0 < rows < whole.x.shape[0]
    saved["x"] = np.zeros_like(saved["x"])
    np.savez_compressed(path, **saved)
    grown = corpus_evidence(303, 14, jobs=1, cache=tmp_path)
    assert not grown.x[:rows].any()
    np.testing.assert_array_equal(grown.x[rows:], whole.x[rows:])
    np.testing.assert_array_equal(grown.y, whole.y)
    np.testing.assert_array_equal(grown.samples, whole.samples)
    assert (grown.rules, grown.family, grown.skipped) == (whole.rules, whole.family, whole.skipped)


def test_evidence_and_shapes_drawn_together_equal_each_drawn_alone(tmp_path: Path) -> None:
    """``model fit`` reads both of each window simulated once: the same numbers as the two
    drawn one after the other, whatever start of each the cache holds."""
    ev_alone, shapes_alone = corpus_evidence(303, 10, jobs=1), corpus_shapes(303, 10, jobs=1)
    corpus_shapes(303, 4, jobs=1, cache=tmp_path)  # the shapes' start cached, no evidence
    ev, shapes = corpus_evidence_and_shapes(303, 10, jobs=1, cache=tmp_path)
    for got, want in ((ev.x, ev_alone.x), (ev.y, ev_alone.y), (ev.samples, ev_alone.samples),
                      (shapes.channels, shapes_alone.channels),
                      (shapes.scalars, shapes_alone.scalars), (shapes.y, shapes_alone.y),
                      (shapes.judged, shapes_alone.judged)):  # fmt: skip
        np.testing.assert_array_equal(got, want)
    assert (ev.rules, ev.family, ev.skipped) == (ev_alone.rules, ev_alone.family, ev_alone.skipped)
    assert len(list(tmp_path.glob("corpus-*-10.npz"))) == 1
    assert len(list(tmp_path.glob("shapes-*-10.npz"))) == 1
    # both whole in the cache now: read back as saved
    again_ev, again_shapes = corpus_evidence_and_shapes(303, 10, jobs=1, cache=tmp_path)
    np.testing.assert_array_equal(again_ev.x, ev.x)
    np.testing.assert_array_equal(again_shapes.channels, shapes.channels)


def _label(seed: int, index: int, case: CorpusCase, rec: LoopRecord) -> tuple[int, str, int]:
    return index, case.cause, len(rec.pv)


def test_windows_read_by_two_workers_in_order_with_progress_while_they_draw() -> None:
    """``read_windows`` gives what the windows drawn one by one give, in index order, and
    tells its progress as the workers read, not only when a chunk ends."""
    said: list[str] = []
    got = list(read_windows(_label, 303, 2, 12, jobs=2, progress=said.append, every_s=0.0))
    want = [_label(303, i, *draw_case(303, i)) for i in range(2, 12)]
    assert got == want
    assert said[-1].startswith("corpus seed 303: 12/12 windows,"), said
    # with every_s 0 a line comes at each wait for a chunk, each counted as the workers read
    assert len(said) >= 2 and all(re.search(r": \d+/12 windows, \d+/s, ", s) for s in said)
