"""Where the fit's cached corpus files of fewer windows can start a longer one.

Window ``i`` of corpus ``seed`` depends on the seed and the index alone
(``simulator.corpus.draw_case``), so the first ``m`` windows of a file of ``n > m`` are those
of the file of ``m``: a cached file is read as a longer one's start and only the rest are
drawn (the shape network reads four times the trees' windows, and the windows cost most of a fit).
"""

from __future__ import annotations

from pathlib import Path


def cached_start(cache: Path, stem: str, n: int) -> tuple[Path, int] | None:
    """The file ``{stem}{m}.npz`` in ``cache`` of the most windows ``m`` fewer than ``n``, and
    ``m``; None if there is none."""
    counts = (p.name[len(stem) : -len(".npz")] for p in cache.glob(f"{stem}*.npz"))
    sizes = [int(c) for c in counts if c.isdigit() and 0 < int(c) < n]
    if not sizes:
        return None
    m = max(sizes)
    return cache / f"{stem}{m}.npz", m
