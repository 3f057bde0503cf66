"""Whether the demo's verdicts hold once found (issue 46's demo check), printed as figures.

    python benchmarks/demo_stability.py [--minutes 10] [--port 8765]

Starts ``plantcheck demo`` (100x), polls the loop table every 5 s until every loop shows its
true cause, then for ``--minutes`` more: every change of a loop's state or cause after that
moment is listed with its time, and the count per loop is printed. The issue asks for none.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import httpx

from plantcheck.simulator.scenario import load_scenario


def _table(port: int) -> dict[str, tuple[str, str]] | None:
    try:
        loops = httpx.get(f"http://127.0.0.1:{port}/api/v1/loops", timeout=5).json()
    except (httpx.TransportError, ValueError):
        return None
    return {lp["id"]: (lp["state"], lp["cause"]) for lp in loops}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="watch this long after")
    ap.add_argument("--port", type=int, default=8765, help="the demo's port")
    a = ap.parse_args()
    truth = {spec.id: spec.cause for spec in load_scenario(None).loop}
    demo = subprocess.Popen(
        [sys.executable, "-m", "plantcheck.service.cli", "demo", "--port", str(a.port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        t0 = time.monotonic()
        found: float | None = None
        last: dict[str, tuple[str, str]] = {}
        changes: list[tuple[float, str, tuple[str, str], tuple[str, str]]] = []
        while time.monotonic() - t0 < 180.0 + 60.0 * a.minutes:
            time.sleep(5.0)
            table = _table(a.port)
            if table is None:
                continue
            now = time.monotonic() - t0
            if found is None:
                if all(table.get(k, ("", ""))[1] == v for k, v in truth.items()):
                    found, last = now, table
                    print(f"every loop's true cause after {now:.0f} s", flush=True)
                continue
            for loop, seen in table.items():
                if last.get(loop) != seen:
                    changes.append((now - found, loop, last.get(loop, ("", "")), seen))
                    print(f"  +{now - found:5.0f} s {loop}: {last.get(loop)} -> {seen}", flush=True)
            last = table
            if now - found >= 60.0 * a.minutes:
                break
        if found is None:
            print("the true causes were never all shown within 3 minutes")
            return
        per_loop = {k: sum(1 for c in changes if c[1] == k) for k in truth}
        which = ", ".join(f"{k} {n}" for k, n in per_loop.items() if n)
        print(
            f"{len(changes)} changes of state or cause in {a.minutes:g} minutes after that"
            + (f": {which}" if which else "")
        )
    finally:
        demo.terminate()
        demo.wait(timeout=30)


if __name__ == "__main__":
    main()
