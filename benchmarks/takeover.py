"""How long a standby ``plantcheck run`` takes to lead after the leader is killed (issue 28).

Starts a throw-away PostgreSQL cluster on loopback, imports the default plant's records and runs
two ``plantcheck run`` processes on the one database. Then, ``--kills`` times: ``kill -9`` the
leader, time until the other's ``/readyz`` says ``"role": "leader"`` (polled every 0.1 s), and
start the killed one again as the standby. Prints each takeover and their min / median / max.

A takeover is the standby's wait for its next poll of the scheduler lock (up to ``--poll`` s,
``[scheduler] takeover_poll_s``), PostgreSQL freeing the dead session's advisory lock, and the
new leader starting its scheduler and sources. ``--cpu-load N`` runs N busy processes beside it
(a loaded CI machine: the test suite's distributed test once read 5.2 s there).

    python benchmarks/takeover.py [--kills 10] [--poll 2] [--cpu-load 0]
"""

from __future__ import annotations

import argparse
import random
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from cpu_load import busy_processes
from helpers import free_port
from pgcluster import PgCluster, available
from servicehelpers import CLI, fill_store, write_config


def _role(port: int) -> str | None:
    try:
        r = httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=2)
        return str(r.json().get("role")) if r.status_code in (200, 503) else None
    except (httpx.TransportError, ValueError):
        return None


def _until(port: int, role: str, timeout_s: float) -> None:
    """Wait until the run on ``port`` says ``role`` in ``/readyz`` (polled every 0.1 s)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if _role(port) == role:
            return
        time.sleep(0.1)
    raise SystemExit(f"the run on port {port} not {role} within {timeout_s:g} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kills", type=int, default=10, help="leaders killed in turn")
    ap.add_argument("--poll", type=float, default=2.0, help="takeover_poll_s (s)")
    ap.add_argument("--cpu-load", type=int, default=0, help="busy processes beside it")
    args = ap.parse_args()
    if (reason := available()) is not None:
        sys.exit(f"takeover.py needs PostgreSQL: {reason}")
    folder = Path(tempfile.mkdtemp(prefix="plantcheck-takeover-"))
    cluster = PgCluster()
    cluster.start()
    procs: dict[int, subprocess.Popen[bytes]] = {}
    try:
        url = cluster.create_database(f"t{uuid.uuid4().hex[:8]}")
        ports = [free_port(), free_port()]
        configs = []
        for k, port in enumerate(ports):
            text = write_config(folder, port=port, period_s=10.0).read_text()
            text = re.sub(r'url = "sqlite\+aiosqlite:///[^"]*"', f'url = "{url}"', text, count=1)
            text = text.replace("buffer.db", f"buffer-{k}.db")
            text = text.replace("[scheduler]\n", f"[scheduler]\ntakeover_poll_s = {args.poll:g}\n")
            configs.append(folder / f"run-{k}.toml")
            configs[-1].write_text(text, encoding="utf-8")
        print("importing the default plant's records ...", flush=True)
        fill_store(folder, configs[0])

        def start(k: int) -> None:
            with (folder / f"run-{k}.log").open("ab") as log:
                procs[k] = subprocess.Popen(
                    [*CLI, "run", "--config", str(configs[k])], stdout=log, stderr=log
                )

        start(0)
        _until(ports[0], "leader", 120)
        start(1)
        _until(ports[1], "standby", 120)
        times = []
        leader = 0
        phase = random.Random(0)
        with busy_processes(args.cpu_load):
            for i in range(args.kills):
                # the standby settled, killed at any phase of its poll
                time.sleep(1 + phase.uniform(0, args.poll))
                procs[leader].send_signal(signal.SIGKILL)
                procs[leader].wait()
                t0 = time.monotonic()
                other = 1 - leader
                _until(ports[other], "leader", 120)
                times.append(time.monotonic() - t0)
                print(f"kill {i + 1:2d}: run-{other} leads after {times[-1]:.2f} s", flush=True)
                start(leader)
                _until(ports[leader], "standby", 120)
                leader = other
        print(
            f"\ntakeover after kill -9, {args.kills} kills, takeover_poll_s {args.poll:g} s, "
            f"{args.cpu_load} busy processes: min {min(times):.2f} s, median "
            f"{statistics.median(times):.2f} s, max {max(times):.2f} s"
        )
        print(f"logs in {folder}")
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait(10)
        cluster.destroy()


if __name__ == "__main__":
    main()
