"""The worst ``GET /loops/{id}/samples`` request the API allows, on a loop with 3 M samples
(issue 45): its time and the memory it costs the service, alone and 200 at once, and what
those 200 do to ``/healthz``.

A real ``plantcheck run`` over a SQLite file holding 1 M samples of each of SP, PV and OP (one
a second, 11.6 days); the worst request allowed asks for the longest page (10,000) after the
largest offset (10,000) over the whole span, all signals; the cursor page is the one the
``Link`` header leads to near the end.

    python benchmarks/api_worst_request.py [--samples 1000000] [--parallel 200]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from proctree import rss_kb
from soak import Drill, free_port

from plantcheck.storage.database import upgrade

CLI = [sys.executable, "-m", "plantcheck.service.cli"]
T0_US = 1_767_225_600_000_000
"""2026-01-01T00:00:00Z: the first sample."""


def write_config(folder: Path, port: int) -> Path:
    path = folder / "plantcheck.toml"
    path.write_text(
        f'[storage]\nurl = "sqlite+aiosqlite:///{folder / "big.db"}"\n'
        f'buffer_path = "{folder / "buffer.db"}"\n\n[api]\nport = {port}\n\n'
        f'[[source]]\nname = "plc"\nprotocol = "modbus"\nport = {free_port()}\n'
        "down_grace_s = 86400\n\n"
        '[[loop]]\nid = "FIC1"\ntype = "flow"\nsource = "plc"\n'
        'sp = "hr:0:float32"\npv = "hr:2:float32"\nop = "hr:4:float32"\n',
        encoding="utf-8",
    )
    return path


def fill(db: Path, per_signal: int) -> None:
    """``per_signal`` samples a second of each of the loop's three tags."""
    with sqlite3.connect(db) as con:
        tags = [r[0] for r in con.execute("SELECT id FROM tags ORDER BY id")]
        step = 100_000
        for tag in tags:
            for k0 in range(0, per_signal, step):
                con.executemany(
                    "INSERT INTO samples (tag_id, ts_us, recv_us, value, status) "
                    "VALUES (?, ?, ?, ?, 0)",
                    (
                        (tag, T0_US + k * 1_000_000, T0_US + k * 1_000_000, 50.0 + k % 97 / 10)
                        for k in range(k0, min(per_signal, k0 + step))
                    ),
                )
        con.commit()


class PeakRss:
    """The service's peak resident memory while running (sampled every 5 ms)."""

    def __init__(self, pid: int) -> None:
        self.pid, self.peak, self._stop = pid, 0, threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def _watch(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, rss_kb(self.pid))
            time.sleep(0.005)

    def __enter__(self) -> PeakRss:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self._thread.join()


PROBE = """
import sys, time, json, os, httpx
url, stop = sys.argv[1], sys.argv[2]
out = []
with httpx.Client(timeout=60) as c:
    while not os.path.exists(stop):
        t = time.perf_counter()
        assert c.get(url + "/healthz").status_code == 200
        out.append(time.perf_counter() - t)
        time.sleep(0.02)
print(json.dumps(out))
"""


async def parallel(url: str, params: dict[str, str], n: int, folder: Path) -> list[float]:
    """``n`` worst requests at once: their times. ``/healthz`` is asked every 20 ms meanwhile
    by another process (a client in this one would wait behind its own 200 connections)."""
    limits = httpx.Limits(max_connections=n + 5)
    async with httpx.AsyncClient(timeout=600, limits=limits) as client:

        async def one() -> float:
            t = time.perf_counter()
            r = await client.get(f"{url}/api/v1/loops/FIC1/samples", params=params)
            assert r.status_code == 200, r.text
            return time.perf_counter() - t

        return list(await asyncio.gather(*(one() for _ in range(n))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--samples", type=int, default=1_000_000, help="per signal (3 signals)")
    ap.add_argument("--parallel", type=int, default=200)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="plantcheck-worst-") as tmp:
        folder = Path(tmp)
        port = free_port()
        config = write_config(folder, port)
        url = f"sqlite+aiosqlite:///{folder / 'big.db'}"
        upgrade(url)
        subprocess.run([*CLI, "db", "upgrade", "--config", str(config)], check=True,
                       capture_output=True)  # fmt: skip
        t = time.perf_counter()
        # the loop's tags exist once the service has synced its configuration
        svc = subprocess.Popen([*CLI, "run", "--config", str(config)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        Drill._wait_port(port, svc)
        svc.terminate()
        svc.wait(30)
        fill(folder / "big.db", args.samples)
        print(f"filled {3 * args.samples:,} samples in {time.perf_counter() - t:.0f} s")
        svc = subprocess.Popen([*CLI, "run", "--config", str(config)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        try:
            Drill._wait_port(port, svc)
            base = f"http://127.0.0.1:{port}"
            end_iso = "2030-01-01T00:00:00Z"
            worst = {"from": "2026-01-01T00:00:00Z", "to": end_iso, "limit": "10000",
                     "offset": "10000"}  # fmt: skip
            after = f"{T0_US + (args.samples - 5000) * 1_000_000}:1"
            cursor = {"from": "2026-01-01T00:00:00Z", "to": end_iso, "limit": "10000",
                      "after": after}  # fmt: skip
            with httpx.Client(timeout=600) as client:
                client.get(f"{base}/api/v1/loops/FIC1/samples", params=worst)  # warm
                print("request                         time (median of 5)   service memory +")
                for name, params in (("offset 10,000 + 10,000", worst), ("cursor page", cursor)):
                    rss0 = rss_kb(svc.pid)
                    times = []
                    with PeakRss(svc.pid) as peak:
                        for _ in range(5):
                            t = time.perf_counter()
                            r = client.get(f"{base}/api/v1/loops/FIC1/samples", params=params)
                            times.append(time.perf_counter() - t)
                            assert r.status_code == 200 and len(r.json()) > 0, r.text
                    print(f"{name:30s} {1000 * statistics.median(times):8.0f} ms"
                          f"           {(peak.peak - rss0) / 1024:6.1f} MB")  # fmt: skip
            rss0 = rss_kb(svc.pid)
            stop = folder / "stop-probe"
            prober = subprocess.Popen([sys.executable, "-c", PROBE, base, str(stop)],
                                      stdout=subprocess.PIPE, text=True)  # fmt: skip
            time.sleep(1.0)
            with PeakRss(svc.pid) as peak:
                times = asyncio.run(parallel(base, worst, args.parallel, folder))
            stop.touch()
            health = json.loads(prober.communicate(timeout=60)[0])
            health.sort()
            print(
                f"{args.parallel} at once: slowest {max(times):.1f} s, median "
                f"{statistics.median(times):.1f} s; service memory +{(peak.peak - rss0) / 1024:.0f}"
                f" MB; /healthz max {1000 * health[-1]:.0f} ms, p95 "
                f"{1000 * health[int(0.95 * (len(health) - 1))]:.0f} ms over {len(health)} probes"
            )
        finally:
            svc.terminate()
            svc.wait(30)


if __name__ == "__main__":
    main()
