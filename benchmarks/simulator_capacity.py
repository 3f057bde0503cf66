"""Simulator capacity: loops served at 1 Hz with no lag growth, and the reachable speed-up.

1. Capacity: N copies of the default scenario's loops, Modbus only, real time (1 s per step),
   while a separate process reads the *whole* register map once per second with pymodbus
   (the load of a poller). The plant keeps up when its lag behind schedule does not grow
   (max lag over the last half < 0.5 s). Target: >= 2,000 loops.
2. Speed-up: the default 11-loop scenario with both servers (Modbus and OPC UA, every step
   written to OPC UA) at increasing --speed; achieved = simulated s per wall s. Target >= 100x.

Usage: python benchmarks/simulator_capacity.py [--loops 1000 2000 4000] [--seconds 20]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

from plantcheck.simulator.runner import PlantRunner

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from simhelpers import scaled_scenario


def _reader(port: int, n_regs: int, seconds: float, out: mp.Queue) -> None:  # type: ignore[type-arg]
    from pymodbus.client import AsyncModbusTcpClient

    async def main() -> None:
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=5)
        for _ in range(100):
            if await client.connect():
                break
            await asyncio.sleep(0.1)
        full, durations = 0, []
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            t0 = time.monotonic()
            for a in range(0, n_regs, 125):
                r = await client.read_holding_registers(a, count=min(125, n_regs - a), device_id=1)
                if r.isError():
                    break
            else:
                full += 1
            durations.append(time.monotonic() - t0)
            await asyncio.sleep(max(0.0, 1.0 - (time.monotonic() - t0)))
        client.close()
        out.put((full, float(np.median(durations)) if durations else float("nan")))

    asyncio.run(main())


async def _run_for(runner: PlantRunner, seconds: float) -> tuple[float, int]:
    task = asyncio.create_task(runner.run())
    await runner.ready.wait()
    steps0, t0 = runner.plant.steps, time.monotonic()
    await asyncio.sleep(seconds)
    steps = runner.plant.steps - steps0
    wall = time.monotonic() - t0
    runner.stop()
    await task
    return wall, steps


def capacity(n: int, seconds: float) -> dict[str, float]:
    sc = scaled_scenario(n)
    port = sc.modbus.port
    runner = PlantRunner(sc)
    assert runner.modbus is not None
    q: mp.Queue = mp.Queue()  # type: ignore[type-arg]
    reader = mp.Process(target=_reader, args=(port, runner.modbus.n_registers, seconds, q))
    reader.start()
    wall, steps = asyncio.run(_run_for(runner, seconds + 1))
    reader.join()
    full, read_s = q.get()
    lags = np.array(runner.stats.lags)
    half = lags[len(lags) // 2 :]
    return {
        "loops": n,
        "steps": steps,
        "wall_s": wall,
        "max_lag_s": float(half.max()) if half.size else float("nan"),
        "median_lag_s": float(np.median(half)) if half.size else float("nan"),
        "map_reads": full,
        "map_read_s": read_s,
    }


def speedup(speed: float, seconds: float) -> float:
    sc = scaled_scenario(8, speed=speed, opcua=True)
    runner = PlantRunner(sc)
    wall, steps = asyncio.run(_run_for(runner, seconds))
    return steps * sc.clock.sample_time_s / wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loops", type=int, nargs="+", default=[1000, 2000, 3000, 4000, 6000])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--speeds", type=float, nargs="+", default=[100, 300, 1000, 3000])
    args = ap.parse_args()
    print("capacity (Modbus, 1 s per step, whole map read once a second by a client process)")
    print(
        "  loops  steps  max lag (s, 2nd half)  median lag (s)  map reads  map read (s)  keeps up"
    )
    best = 0
    for n in args.loops:
        r = capacity(n, args.seconds)
        ok = r["max_lag_s"] < 0.5 and r["map_reads"] >= args.seconds * 0.8
        best = max(best, n) if ok else best
        print(
            f"  {n:5d}  {r['steps']:5.0f}  {r['max_lag_s']:21.3f}  {r['median_lag_s']:14.3f}"
            f"  {r['map_reads']:9.0f}  {r['map_read_s']:12.3f}  {'yes' if ok else 'no'}"
        )
    print(f"largest loop count served at 1 Hz with no lag growth: {best} (target >= 2000)")
    print("speed-up (default 11-loop scenario, Modbus + OPC UA, every step written to OPC UA)")
    reached = 0.0
    for s in args.speeds:
        got = speedup(s, 5.0)
        print(f"  requested {s:7.0f}x  achieved {got:8.1f}x")
        if got >= 0.95 * s:
            reached = max(reached, s)
    print(f"speed-up reached: {reached:.0f}x real time (target >= 100x)")


if __name__ == "__main__":
    main()
