"""A site on one PostgreSQL (issue 28): simulated servers, collectors, workers, one service.

Starts a throw-away PostgreSQL cluster on loopback, ``--servers`` simulator processes serving
``--loops`` loops in all over Modbus TCP at 1 s (copies of the default plant's loops), one
``plantcheck ingest --collector`` per ``--collectors`` (the servers shared round-robin), one
``plantcheck run`` with ``engine = "queue"`` and ``--workers`` ``plantcheck worker`` processes,
all real processes, for ``--minutes``. Prints:

- values stored per second (PostgreSQL's insert counter of the samples table);
- ingest lag: how old each sample of 40 random PV tags is when it is first seen stored
  (polled every 0.2 s; p50, p99): the source's sample time to the commit;
- loops diagnosed per minute and the time the first pass over every loop took (the windows are
  as long as the run: short windows are diagnosed faster than 2-hour ones, so take the
  per-core diagnosis throughput on full windows from ``benchmarks/service.py``);
- ``GET /api/v1/loops`` latency with every loop in the table (p50, p99 of 1,000 requests, one
  client at a time, while the site runs);
- CPU (cores used on average) and memory (RSS, with child processes) per process.

    python benchmarks/scale.py [--loops 10000] [--servers 4] [--collectors 2] [--workers 2]
                               [--minutes 6] [--period 300]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import os
import random
import subprocess
import sys
import time
import uuid
from pathlib import Path

import httpx
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from helpers import free_port
from pgcluster import PgCluster, available
from proctree import cpu_s, rss_kb
from simhelpers import scaled_scenario

from plantcheck.simulator.export import map_toml
from plantcheck.simulator.scenario import LoopSpec, Scenario
from plantcheck.storage.database import upgrade

CLI = [sys.executable, "-m", "plantcheck.service.cli"]


def _server_scenario(k: int, n: int) -> Scenario:
    sc = scaled_scenario(n)
    loops = [LoopSpec.model_validate({**lp.model_dump(), "id": f"U{k}-{lp.id}"}) for lp in sc.loop]
    return sc.model_copy(update={"loop": loops})


def _serve(sc: Scenario) -> None:
    from plantcheck.simulator.runner import PlantRunner

    asyncio.run(PlantRunner(sc).run())


def _config(folder: Path, url: str, api_port: int, scenarios: list[Scenario], collectors: int,
            period_s: float) -> Path:  # fmt: skip
    parts = [
        "[storage]",
        f'url = "{url}"',
        f'buffer_path = "{folder / "service-buffer.db"}"',
        "[api]",
        f"port = {api_port}",
        "[scheduler]",
        'engine = "queue"',
        "batch_size = 100",
        "window_s = 7200",
        f"period_s = {period_s:g}",
        "",
    ]
    for k, sc in enumerate(scenarios):
        tables = map_toml(sc, protocol="modbus", source=f"srv{k}", poll_interval_s=1.0)
        tables = tables.replace(
            'protocol = "modbus"\n', f'protocol = "modbus"\ncollector = "edge{k % collectors}"\n', 1
        )
        parts.append(tables)
    path = folder / "site.toml"
    path.write_text("\n".join(parts), encoding="utf-8")
    return path


async def _measure(url: str, api: str, tag_ids: list[int], n_loops: int, minutes: float,
                   warmup_s: float) -> dict[str, object]:  # fmt: skip
    import asyncpg

    conn = await asyncpg.connect(url.replace("postgresql+asyncpg", "postgresql"))
    ins = "SELECT n_tup_ins FROM pg_stat_user_tables WHERE relname = 'samples'"
    lags: list[float] = []
    t_start = time.monotonic()
    first_pass_s = None
    t_warm = t_start + warmup_s
    ins0 = d0 = None
    t_ins0 = t_start
    probe = random.Random(1).sample(tag_ids, min(40, len(tag_ids)))
    seen = {t: time.time_ns() // 1000 for t in probe}
    t_pass = 0.0
    while time.monotonic() - t_start < minutes * 60:
        await asyncio.sleep(0.2)
        rows = await conn.fetch(
            "SELECT tag_id, ts_us FROM samples WHERE tag_id = ANY($1::int[]) AND ts_us > $2",
            probe,
            min(seen.values()),
        )
        now_us = time.time_ns() // 1000
        warm = time.monotonic() >= t_warm
        for r in rows:
            if r["ts_us"] > seen[r["tag_id"]]:
                if warm:  # each new sample's age when it is first seen stored (within 0.2 s)
                    lags.append((now_us - r["ts_us"]) / 1e6)
                seen[r["tag_id"]] = max(seen[r["tag_id"]], r["ts_us"])
        if warm and ins0 is None:
            ins0, t_ins0 = await conn.fetchval(ins), time.monotonic()
            d0 = await conn.fetchval("SELECT count(*) FROM diagnoses")
        if first_pass_s is None and time.monotonic() - t_pass > 2:
            t_pass = time.monotonic()
            done = await conn.fetchval(
                "SELECT count(*) FROM loops WHERE last_diagnosis_us IS NOT NULL"
            )
            if done >= n_loops:
                first_pass_s = time.monotonic() - t_start
    span = time.monotonic() - t_ins0
    values_s = (await conn.fetchval(ins) - ins0) / span
    diagnosed = (await conn.fetchval("SELECT count(*) FROM diagnoses") - d0) / (span / 60)
    await conn.close()
    lat = []
    async with httpx.AsyncClient(timeout=30) as client:
        for _ in range(1000):
            t0 = time.perf_counter()
            r = await client.get(f"{api}/api/v1/loops")
            lat.append(time.perf_counter() - t0)
            assert r.status_code == 200 and len(r.json()) == n_loops
    return {
        "values_s": values_s,
        "lag_p50": float(np.percentile(lags, 50)) if lags else float("nan"),
        "lag_p99": float(np.percentile(lags, 99)) if lags else float("nan"),
        "diagnosed_per_min": diagnosed,
        "first_pass_s": first_pass_s,
        "api_p50_ms": 1000 * float(np.percentile(lat, 50)),
        "api_p99_ms": 1000 * float(np.percentile(lat, 99)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--loops", type=int, default=10000)
    ap.add_argument("--servers", type=int, default=4)
    ap.add_argument("--collectors", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--minutes", type=float, default=6.0)
    ap.add_argument("--period", type=float, default=300.0)
    ap.add_argument("--warmup", type=float, default=60.0, help="seconds before measuring")
    args = ap.parse_args()
    if (reason := available()) is not None:
        sys.exit(f"scale.py needs PostgreSQL: {reason}")
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="plantcheck-scale-"))
    cluster = PgCluster()
    cluster.start()
    procs: dict[str, subprocess.Popen[bytes]] = {}
    servers: list[mp.Process] = []
    try:
        url = cluster.create_database(f"s{uuid.uuid4().hex[:8]}")
        upgrade(url)
        per = [
            args.loops // args.servers + (k < args.loops % args.servers)
            for k in range(args.servers)
        ]
        scenarios = [_server_scenario(k, n) for k, n in enumerate(per)]
        ctx = mp.get_context("spawn")
        for sc in scenarios:
            p = ctx.Process(target=_serve, args=(sc,), daemon=True)
            p.start()
            servers.append(p)
        api_port = free_port()
        site = _config(folder, url, api_port, scenarios, args.collectors, args.period)

        def start(name: str, *cli: str, config: Path = site) -> None:
            log = (folder / f"{name}.log").open("wb")
            procs[name] = subprocess.Popen([*CLI, *cli, "--config", str(config)], stdout=log,
                                           stderr=subprocess.STDOUT)  # fmt: skip

        time.sleep(5)  # the servers bind their ports
        for c in range(args.collectors):
            own = folder / f"edge{c}.toml"
            own.write_text(site.read_text().replace("service-buffer.db", f"edge{c}-buffer.db"))
            start(f"collector-{c}", "ingest", "--collector", f"edge{c}", config=own)
        start("service", "run")
        for w in range(args.workers):
            start(f"worker-{w}", "worker", "--concurrency", "1")
        api = f"http://127.0.0.1:{api_port}"
        for _ in range(600):
            for name, p in procs.items():
                if p.poll() is not None:
                    tail = (folder / f"{name}.log").read_text(errors="replace")[-2000:]
                    raise SystemExit(f"{name} exited with {p.returncode}:\n{tail}")
            try:
                if httpx.get(f"{api}/readyz", timeout=2).status_code in (200, 503):
                    break
            except httpx.TransportError:
                time.sleep(0.5)
        tag_ids = _tag_ids(url)
        cpu0 = {n: cpu_s(p.pid) for n, p in procs.items()} | {
            f"simulator-{k}": cpu_s(s.pid or 0) for k, s in enumerate(servers)
        }
        t0 = time.monotonic()
        res = asyncio.run(_measure(url, api, tag_ids, args.loops, args.minutes, args.warmup))
        wall = time.monotonic() - t0
        pids = {n: p.pid for n, p in procs.items()} | {
            f"simulator-{k}": s.pid or 0 for k, s in enumerate(servers)
        }
        print(f"\n{args.loops} loops on {args.servers} simulated servers (Modbus, 1 s), "
              f"{args.collectors} collectors, {args.workers} workers, {args.minutes:g} min "
              f"on {os.cpu_count()} cores")  # fmt: skip
        print(f"values stored:          {res['values_s']:,.0f} /s")
        print(f"ingest lag:             p50 {res['lag_p50']:.2f} s, p99 {res['lag_p99']:.2f} s")
        fp = res["first_pass_s"]
        print(f"loops diagnosed:        {res['diagnosed_per_min']:,.0f} /min; first pass over "
              f"every loop {'not finished' if fp is None else f'{fp:.0f} s'}")  # fmt: skip
        print(f"GET /api/v1/loops:      p50 {res['api_p50_ms']:.0f} ms, "
              f"p99 {res['api_p99_ms']:.0f} ms ({args.loops} loops)")  # fmt: skip
        print("process           cores   RSS MB")
        for n, pid in pids.items():
            cores = (cpu_s(pid) - cpu0.get(n, 0.0)) / wall
            print(f"  {n:15s} {cores:6.2f} {rss_kb(pid) / 1024:8.0f}")
        print(f"logs in {folder}")
    finally:
        for p in procs.values():
            p.terminate()
        for p in procs.values():
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
        for s in servers:
            s.kill()
        cluster.destroy()


def _tag_ids(url: str) -> list[int]:
    import asyncpg

    async def run() -> list[int]:
        conn = await asyncpg.connect(url.replace("postgresql+asyncpg", "postgresql"))
        for _ in range(120):
            ids = [r["id"] for r in await conn.fetch("SELECT id FROM tags WHERE signal = 'pv'")]
            if ids:
                await conn.close()
                return ids
            await asyncio.sleep(1)
        await conn.close()
        raise SystemExit("no tags stored: did the collectors start? (see their logs)")

    return asyncio.run(run())


if __name__ == "__main__":
    main()
