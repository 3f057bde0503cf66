"""Ingest throughput: simulator → Modbus poller → store, against a bare pymodbus read loop.

The simulator serves 1,000 loops (SP, PV, OP, MV: 4,000 values, 40 blocks of 100 registers)
at 1 s; the poller reads them every second and the writer commits once a second.

- sustained: values/s stored over ``--seconds`` and the writer's queue depth at the end
  (no growing lag = depth stays below one second of values);
- burst: 500,000 samples written straight to the store (values/s);
- ratio: sustained values/s of the full ingest / values/s read by a bare pymodbus loop that
  decodes and stores nothing.

Targets: >= 20,000 values/s into SQLite and >= 100,000 into PostgreSQL in burst; ratio >= 0.7.
PostgreSQL needs Debian's server binaries (a throw-away cluster is started on a loopback port).

Usage: python benchmarks/ingest.py [--seconds 20] [--loops 1000] [--no-postgres]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from pgcluster import PgCluster, available
from pymodbus.client import AsyncModbusTcpClient
from simhelpers import scaled_scenario

from plantcheck.connectors.modbus import Block, ModbusTag, plan_blocks
from plantcheck.core.samples import Sample
from plantcheck.service.config import Config, LoopConfig, SourceConfig, StorageConfig
from plantcheck.service.ingest import Ingestion
from plantcheck.simulator.runner import PlantRunner
from plantcheck.storage.database import upgrade
from plantcheck.storage.store import Store


def plant(n: int) -> tuple[PlantRunner, int]:
    """The benchmark plant (Modbus only, real time) and its Modbus port."""
    sc = scaled_scenario(n)
    return PlantRunner(sc), sc.modbus.port


async def bare_read_loop(host: str, port: int, blocks: list[Block], seconds: float) -> int:
    """Reference: read all blocks once a second, decode nothing, store nothing; returns the
    number of tag values read."""
    client = AsyncModbusTcpClient(host, port=port, timeout=5, retries=0)
    await client.connect()
    n = 0
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        t0 = time.monotonic()
        for b in blocks:
            r = await client.read_holding_registers(b.start, count=b.count, device_id=1)
            n += len(b.tags)
            _ = r.registers
        await asyncio.sleep(max(0.0, 1.0 - (time.monotonic() - t0)))
    client.close()
    return n


def config(url: str, port: int, n: int, buffer: Path) -> Config:
    loops = [
        LoopConfig(
            id=f"L{i:05d}",
            source="sim",
            **{
                s: f"hr:{10 + 10 * i + 2 * j}:float32"
                for j, s in enumerate(("sp", "pv", "op", "mv"))
            },
        )
        for i in range(n)
    ]
    return Config(
        storage=StorageConfig(url=url, buffer_path=str(buffer)),
        source=[SourceConfig(name="sim", protocol="modbus", port=port, timeout_s=5)],
        loop=loops,
    )


async def sustained(url: str, n: int, seconds: float, tmp: Path) -> tuple[float, int]:
    runner, port = plant(n)
    task = asyncio.create_task(runner.run())
    await runner.ready.wait()
    ing = await Ingestion.start(config(url, port, n, tmp / f"buf{port}.db"))
    await asyncio.sleep(3.0)  # warm up
    s0, t0 = ing.writer.stats.stored, time.monotonic()
    await asyncio.sleep(seconds)
    rate = (ing.writer.stats.stored - s0) / (time.monotonic() - t0)
    depth = ing.writer.depth
    await ing.stop()
    runner.stop()
    await task
    return rate, depth


async def bare(n: int, seconds: float) -> float:
    runner, port = plant(n)
    task = asyncio.create_task(runner.run())
    await runner.ready.wait()
    tags = [
        ModbusTag.parse(0, f"hr:{10 + 10 * i + 2 * j}:float32") for i in range(n) for j in range(4)
    ]
    got = await bare_read_loop("127.0.0.1", port, plan_blocks(tags), seconds)
    runner.stop()
    await task
    return got / seconds


async def burst(url: str, n_rows: int = 500_000) -> float:
    store = await Store.open(url)
    try:
        lp = await store.ensure_loop(f"burst{time.time_ns()}", signals=["pv"])
        tid = lp.tags["pv"]
        t0_us = 1_767_225_600_000_000
        rows = [Sample(tid, t0_us + k * 1000, t0_us, float(k), 0) for k in range(n_rows)]
        t0 = time.perf_counter()
        for i in range(0, n_rows, 50_000):
            await store.write_samples(rows[i : i + 50_000])
        return n_rows / (time.perf_counter() - t0)
    finally:
        await store.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--loops", type=int, default=1000)
    ap.add_argument("--no-postgres", action="store_true")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="plantcheck-ingest-"))
    bare_rate = asyncio.run(bare(args.loops, args.seconds))
    print(f"bare pymodbus read loop: {bare_rate:,.0f} values/s ({args.loops} loops x 4 at 1 s)")
    targets = [("SQLite", f"sqlite+aiosqlite:///{tmp / 'ingest.db'}", 20_000)]
    cluster = None
    if not args.no_postgres:
        reason = available()
        if reason:
            print(f"PostgreSQL skipped: {reason}")
        else:
            cluster = PgCluster()
            cluster.start()
            targets.append(("PostgreSQL", cluster.url, 100_000))
    try:
        for name, url, target in targets:
            upgrade(url)
            rate, depth = asyncio.run(sustained(url, args.loops, args.seconds, tmp))
            b = asyncio.run(burst(url))
            print(
                f"{name}: sustained {rate:,.0f} values/s (queue at end {depth}), ratio to bare "
                f"{rate / bare_rate:.2f} (target >= 0.7); burst {b:,.0f} values/s "
                f"(target >= {target:,})"
            )
    finally:
        if cluster is not None:
            cluster.destroy()


if __name__ == "__main__":
    main()
