"""Rolling windows kept between diagnoses give exactly the windows a whole read gives."""

from __future__ import annotations

import asyncio

import numpy as np
from helpers import T0, one_loop_config

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import GOOD
from plantcheck.storage.store import LoopRow, Store
from plantcheck.storage.window import LoopWindow
from plantcheck.storage.window_cache import WindowCache, merge_tail, trim_head

S = 1_000_000
HOLD = ("sp", "mode")


def _samples(lp: LoopRow, ks: range) -> list[Sample]:
    rows = []
    for k in ks:
        t = T0 + k * S
        rows.append(Sample(lp.tags["pv"], t, t, 50.0 + np.sin(k / 9.0), GOOD))
        rows.append(Sample(lp.tags["op"], t, t, 40.0 + k % 11, GOOD))
        if k % 250 == 0:  # a set point reported on change only
            rows.append(Sample(lp.tags["sp"], t, t, 50.0 + k / 250, GOOD))
    return rows


def _same(a: LoopWindow, b: LoopWindow) -> None:
    assert a.start_us == b.start_us and a.signals == b.signals
    for sig in ("sp", "pv", "op", "mv", "mode"):
        np.testing.assert_array_equal(a[sig], b[sig])


def test_merge_and_trim() -> None:
    t = np.arange(10, dtype=np.int64)
    cached = {"pv": (t, t * 1.0), "sp": (np.array([2, 7]), np.array([1.0, 2.0]))}
    fresh = {"pv": (np.array([8, 9, 10]), np.array([80.0, 90.0, 100.0]))}
    m = merge_tail(cached, fresh, 8)
    assert m["pv"][0].tolist() == list(range(11)) and m["pv"][1][-3:].tolist() == [80, 90, 100]
    assert m["sp"][0].tolist() == [2, 7]  # before 8 kept; the store had none from 8 on
    tr, before = trim_head(m, {}, 5, HOLD)
    assert tr["pv"][0][0] == 5 and before == {"sp": 1.0}


async def _read_as_whole(
    cache: WindowCache, store: Store, lp: LoopRow, window: int, now: int
) -> None:
    """The scheduler's read through ``cache`` equals a whole read of the same bounds."""
    got = await cache.read_latest(lp, window, HOLD, now)
    _same(got.window, await store.read_window(lp, got.start_us, got.end_us, hold=HOLD))


def test_cached_windows_equal_whole_reads(db_url: str) -> None:
    async def body() -> None:
        store = await Store.open(db_url)
        try:
            lp = (await store.sync_config(one_loop_config()))["FIC1"]
            cache = WindowCache(store, lookback_s=60, refresh_s=3600)
            await store.write_samples(_samples(lp, range(0, 1200)))
            window = 600 * S
            late = T0 + 1490 * S
            for end_k in (1200, 1500, 1800, 2400):
                if end_k > 1200:
                    rows = _samples(lp, range(end_k - 300, end_k))
                    # PV at 1,490 s arrives only after the read at 1,500 s: inside the next
                    # read's look-back and window, so that read must pick it up
                    await store.write_samples(
                        [r for r in rows if (r.ts_us, r.tag_id) != (late, lp.tags["pv"])]
                    )
                if end_k == 1800:
                    await store.write_samples([Sample(lp.tags["pv"], late, late, 99.0, GOOD)])
                await _read_as_whole(cache, store, lp, window, T0 + end_k * S)
            assert cache.full_reads == 1 and cache.tail_reads == 3
            assert 0 < cache.nbytes < 600 * 3 * 16 + 1024
            # refresh due at every read: the cached samples are checked against the store's
            # counts, and read whole again only when a sample was written late, before the
            # look-back (OP was never stored between 1,800 and 2,100 s)
            end = T0 + 2400 * S
            refreshing = WindowCache(store, lookback_s=60, refresh_s=0)
            for _ in range(2):
                await _read_as_whole(refreshing, store, lp, window, end)
            assert (refreshing.full_reads, refreshing.checks, refreshing.tail_reads) == (1, 1, 1)
            t = T0 + 1900 * S
            await store.write_samples([Sample(lp.tags["op"], t, t, None, GOOD)])
            await _read_as_whole(refreshing, store, lp, window, end)
            assert refreshing.full_reads == 2 and refreshing.checks == 1
            # no room: every read is whole, nothing kept
            tiny = WindowCache(store, max_bytes=0)
            for _ in range(2):
                await _read_as_whole(tiny, store, lp, window, end)
            assert tiny.full_reads == 2 and len(tiny) == 0 and tiny.nbytes == 0
        finally:
            await store.close()

    asyncio.run(body())


def test_latest_window_ends_at_newest_pv(db_url: str) -> None:
    """``read_latest`` (the scheduler's read) ends each window just after the newest stored PV
    sample, takes it from the tail it reads, and matches a whole read of the same bounds; a
    window shorter than configured (the data stored so far) says it is filling."""

    async def body() -> None:
        store = await Store.open(db_url)
        try:
            lp = (await store.sync_config(one_loop_config()))["FIC1"]
            cache = WindowCache(store, lookback_s=60, refresh_s=3600)
            window = 600 * S
            first = await cache.read_latest(lp, window, HOLD, T0)
            assert first.notes == ["no PV sample stored yet"] and cache.full_reads == 1
            assert not first.filling  # nothing stored: a window of the configured length
            await store.write_samples(_samples(lp, range(0, 300)))
            short = await cache.read_latest(lp, window, HOLD, T0 + 400 * S)
            assert (short.start_us, short.end_us) == (T0, T0 + 299 * S + 1)
            assert "window shortened to the 299 s" in short.notes[0] and short.filling
            for end_k in (900, 1200, 1500):
                await store.write_samples(_samples(lp, range(end_k - 600, end_k)))
                # an OP sample newer than every PV sample stays out until PV reaches it
                t = T0 + (end_k + 5) * S
                await store.write_samples([Sample(lp.tags["op"], t, t, 1.0, GOOD)])
                now = T0 + (end_k + 100) * S  # the server's clock, ahead of the plant's
                got = await cache.read_latest(lp, window, HOLD, now)
                assert got.end_us == T0 + (end_k - 1) * S + 1 and not got.notes
                assert not got.filling
                assert got.start_us == got.end_us - window
                _same(got.window, await store.read_window(lp, got.start_us, got.end_us, hold=HOLD))
            assert cache.full_reads == 2 and cache.tail_reads == 3
            stale = await cache.read_latest(lp, window, HOLD, T0 + 5_000 * S)
            assert (
                stale.end_us == T0 + 5_000 * S
                and "no PV sample stored in the last" in (stale.notes[0])
                and not stale.filling
            )
        finally:
            await store.close()

    asyncio.run(body())
