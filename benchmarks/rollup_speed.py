"""Hourly roll-ups (``storage/rollups.py``): how long one hourly roll-up of a site takes.

Fills a throw-away PostgreSQL 15 (and a SQLite file) with ``--tags`` tags of one sample a
second over ``--hours`` hours, then times the first roll-up (every hour of every tag) and an
hourly one (the new hour and the two before it, as the writer runs it), and prints the time per
tag and the rows per second read, so a site can tell how much of an hour its roll-up takes.

    python benchmarks/rollup_speed.py [--tags 500] [--hours 3]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
import uuid
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from pgcluster import PgCluster, available

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import GOOD
from plantcheck.storage.database import upgrade
from plantcheck.storage.rollups import HOUR_US, roll_up
from plantcheck.storage.store import Store

T0 = 1_700_000_000 // 3600 * HOUR_US


async def measure(url: str, n_tags: int, hours: int) -> None:
    store = await Store.open(url)
    try:
        tag_ids = []
        for i in range(0, n_tags, 4):
            loop = await store.ensure_loop(f"L{i:05d}", signals=("sp", "pv", "op", "mv"))
            tag_ids += list(loop.tags.values())
        tag_ids = tag_ids[:n_tags]
        t0 = time.perf_counter()
        for h in range(hours):
            for k in range(0, 3600, 600):  # ten minutes of every tag per write
                base = T0 + h * HOUR_US + k * 1_000_000
                rows = [
                    Sample(tag, base + s * 1_000_000, base, float(s % 97), GOOD)
                    for tag in tag_ids
                    for s in range(600)
                ]
                await store.write_samples(rows)
        filled = time.perf_counter() - t0
        n_rows = n_tags * hours * 3600
        t0 = time.perf_counter()
        first = await roll_up(store, T0 + hours * HOUR_US, tag_ids)
        t_first = time.perf_counter() - t0
        t0 = time.perf_counter()
        await roll_up(store, T0 + hours * HOUR_US, tag_ids)
        t_hourly = time.perf_counter() - t0
        print(
            f"  {store.dialect:10s} {n_tags} tags x {hours} h at 1 s ({n_rows:,} samples, "
            f"written in {filled:.0f} s): first roll-up {t_first:.2f} s ({first} hours, "
            f"{n_rows / t_first:,.0f} samples/s); hourly roll-up (3 h per tag) {t_hourly:.2f} s, "
            f"{1000 * t_hourly / n_tags:.2f} ms per tag"
        )
    finally:
        await store.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--tags", type=int, default=500)
    ap.add_argument("--hours", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite+aiosqlite:///{Path(tmp) / 'store.db'}"
        upgrade(url)
        asyncio.run(measure(url, args.tags, args.hours))
    reason = available()
    if reason:
        print(f"  PostgreSQL skipped: {reason}")
        return
    cluster = PgCluster()
    cluster.start()
    try:
        url = cluster.create_database(f"b{uuid.uuid4().hex[:12]}")
        upgrade(url)
        asyncio.run(measure(url, args.tags, args.hours))
    finally:
        cluster.stop()


if __name__ == "__main__":
    main()
