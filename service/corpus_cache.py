"""The fit's corpus files: read from the cache where whole, the missing windows drawn once.

Window ``i`` of corpus ``seed`` depends on the seed and the index alone
(``simulator.corpus.draw_case``), so the first ``m`` windows of a file of ``n > m`` are those
of the file of ``m``: a cached file is read as a longer one's start and only the rest are
drawn (the shape network reads four times the trees' windows, and the windows cost most of a fit).

A window's simulation costs most of what reading it costs: two thirds of the chain's evidence
and nearly all of the shapes (400 windows of seed 4242 on one core, 2026-12-01: simulated 13.2
s, with their evidence 19.6 s, with their shapes 13.7 s). Where several kinds of file of the
same seed miss windows (``model fit`` reads the evidence and the shapes of the same windows),
``corpus_files`` simulates each window once and reads every kind from it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar, cast

from plantcheck.service.corpus_draw import read_windows
from plantcheck.simulator.corpus import CorpusCase
from plantcheck.simulator.loop import LoopRecord

T = TypeVar("T")
R = TypeVar("R")
R_contra = TypeVar("R_contra", contravariant=True)
T_co = TypeVar("T_co", covariant=True)


class Collector(Protocol[R_contra, T_co]):
    """Where one kind's windows go as they are read, in index order (a kind may keep them
    in preallocated arrays: 256,000 windows' shapes as Python objects would take gigabytes)."""

    def add(self, row: R_contra) -> None: ...

    def result(self) -> T_co: ...


@dataclass(frozen=True)
class CorpusKind(Generic[R, T]):
    """One kind of cached corpus file. ``stem(seed)``: its name less the window count and
    ``.npz``; ``read(seed, index, case, record)``: one window's row, in a worker process (a
    module-level function); ``collect(count)``: a collector of ``count`` rows;
    ``joined(head, tail)``, ``load(path)``, ``save(path, value)``."""

    stem: Callable[[int], str]
    read: Callable[[int, int, CorpusCase, LoopRecord], R]
    collect: Callable[[int], Collector[R, T]]
    joined: Callable[[T, T], T]
    load: Callable[[Path], T]
    save: Callable[[Path, T], None]


def cached_start(cache: Path, stem: str, n: int) -> tuple[Path, int] | None:
    """The file ``{stem}{m}.npz`` in ``cache`` of the most windows ``m`` fewer than ``n``, and
    ``m``; None if there is none."""
    counts = (p.name[len(stem) : -len(".npz")] for p in cache.glob(f"{stem}*.npz"))
    sizes = [int(c) for c in counts if c.isdigit() and 0 < int(c) < n]
    if not sizes:
        return None
    m = max(sizes)
    return cache / f"{stem}{m}.npz", m


def _read_all(
    reads: tuple[Callable[[int, int, CorpusCase, LoopRecord], Any], ...],
    seed: int,
    index: int,
    case: CorpusCase,
    rec: LoopRecord,
) -> tuple[Any, ...]:
    return tuple(read(seed, index, case, rec) for read in reads)


def corpus_files(
    kinds: Sequence[CorpusKind[Any, Any]],
    seed: int,
    n: int,
    jobs: int | None = None,
    progress: Callable[[str], None] | None = None,
    cache: Path | None = None,
    what: str = "windows",
) -> list[Any]:
    """Each kind's windows 0..n-1 of corpus ``seed``, in the order of ``kinds``: a whole file
    in ``cache`` is read; the windows the others miss beyond their largest cached start are
    simulated once, on ``jobs`` processes (``corpus_draw.read_windows``, progress named
    ``what``), and every such kind read from them. What was drawn is saved in ``cache``."""
    out: list[Any] = [None] * len(kinds)
    todo: dict[int, tuple[Any, int]] = {}  # kind's position -> (cached head or None, first)
    for i, kind in enumerate(kinds):
        path = cache / f"{kind.stem(seed)}{n}.npz" if cache else None
        if path is not None and path.is_file():
            out[i] = kind.load(path)
            continue
        start = cached_start(cache, kind.stem(seed), n) if cache else None
        todo[i] = (None, 0) if start is None else (kind.load(start[0]), start[1])
    if not todo:
        return out
    first = min(f for _, f in todo.values())
    sinks = {i: kinds[i].collect(n - f) for i, (_, f) in todo.items()}
    reads = tuple(kinds[i].read for i in todo)
    rows = read_windows(partial(_read_all, reads), seed, first, n, jobs, progress, what)
    for index, each in enumerate(rows, start=first):
        for (i, (_, f)), row in zip(todo.items(), each, strict=True):
            if index >= f:
                sinks[i].add(row)
    for i, (head, _) in todo.items():
        tail = sinks[i].result()
        out[i] = tail if head is None else kinds[i].joined(head, tail)
        if cache is not None:
            cache.mkdir(parents=True, exist_ok=True)
            kinds[i].save(cache / f"{kinds[i].stem(seed)}{n}.npz", out[i])
    return out


def corpus_file(
    kind: CorpusKind[Any, T],
    seed: int,
    n: int,
    jobs: int | None = None,
    progress: Callable[[str], None] | None = None,
    cache: Path | None = None,
    what: str = "windows",
) -> T:
    """One kind's windows 0..n-1 of corpus ``seed`` (``corpus_files`` of that kind alone)."""
    return cast(T, corpus_files([kind], seed, n, jobs, progress, cache, what)[0])
