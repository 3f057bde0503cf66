"""Soak: the bundled plant's servers, ``plantcheck run`` on them, and a fault every minute.

Real processes on loopback: ``plantcheck simulate`` (Modbus TCP and OPC UA) and ``plantcheck
run`` collecting one loop from each protocol into a SQLite file. Faults in turn: a stall of
both servers, dropped connections, a server restart, the simulator killed with SIGKILL and
started again, the service killed with SIGKILL and started again. At the end, each protocol's
PV history is accounted (``storage.accounting``): samples expected and stored, samples lost
in holes no gap marker covers, marked gaps; then the service's log size and its memory
(the service and its workers, RSS) at start and end.

    python benchmarks/soak.py --minutes 30 [--fault-every 60]

``tests/service/test_fault_suite.py`` runs the same drill with one fault of each kind.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from proctree import rss_kb

from plantcheck.simulator.faults import send_admin
from plantcheck.storage.accounting import SampleAccount, account_samples

CLI = [sys.executable, "-m", "plantcheck.service.cli"]
FAULTS = ("stall", "drop", "restart", "kill-simulator", "kill-service")
LOOPS = {"modbus": "FIC102", "opcua": "FIC101"}
"""The loop collected from each protocol."""
POLL_S = 0.5
"""Modbus poll period and OPC UA sampling interval, s."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Drill:
    """The simulator and the service as processes, faults on demand, the store's account."""

    folder: Path
    speed: float = 1.0
    """Simulated seconds per second; OPC UA stamps samples with the simulated time, so the
    accounting needs 1 (real time)."""
    modbus: int = field(default_factory=free_port)
    opcua: int = field(default_factory=free_port)
    admin: int = field(default_factory=free_port)
    api: int = field(default_factory=free_port)
    sim: subprocess.Popen[bytes] | None = None
    service: subprocess.Popen[bytes] | None = None
    started_at: float = 0.0
    db_dir: Path | None = None
    """Where the database lives (default: ``folder``); the disk-fault tests use a small disk."""
    buffer_dir: Path | None = None
    """Where the durable buffer lives (default: ``folder``)."""

    @property
    def db(self) -> Path:
        return (self.db_dir or self.folder) / "soak.db"

    @property
    def api_url(self) -> str:
        return f"http://127.0.0.1:{self.api}"

    @property
    def log(self) -> Path:
        return self.folder / "service.log"

    @property
    def config(self) -> Path:
        return self.folder / "plantcheck.toml"

    def write_config(self) -> None:
        self.config.write_text(
            f'[storage]\nurl = "sqlite+aiosqlite:///{self.db}"\n'
            f'buffer_path = "{(self.buffer_dir or self.folder) / "buffer.db"}"\n'
            "commit_interval_s = 0.5\n\n"
            f"[api]\nport = {self.api}\n\n"
            "[scheduler]\nwindow_s = 600\nperiod_s = 60\nworkers = 1\n\n"
            f'[[source]]\nname = "plc"\nprotocol = "modbus"\nport = {self.modbus}\n'
            f"poll_interval_s = {POLL_S}\ntimeout_s = 1.0\n\n"
            f'[[source]]\nname = "ua"\nprotocol = "opcua"\n'
            f'url = "opc.tcp://127.0.0.1:{self.opcua}/plantcheck/"\npoll_interval_s = {POLL_S}\n\n'
            f'[[loop]]\nid = "FIC102"\ntype = "flow"\nsource = "plc"\n'
            'sp = "hr:20:float32"\npv = "hr:22:float32"\nop = "hr:24:float32"\n\n'
            f'[[loop]]\nid = "FIC101"\ntype = "flow"\nsource = "ua"\n'
            'sp = "ns=2;s=FIC101.SP"\npv = "ns=2;s=FIC101.PV"\nop = "ns=2;s=FIC101.OP"\n',
            encoding="utf-8",
        )

    def start_simulator(self) -> None:
        self.sim = subprocess.Popen(
            [*CLI, "simulate", "--modbus", f"127.0.0.1:{self.modbus}",
             "--opcua", f"opc.tcp://127.0.0.1:{self.opcua}/plantcheck/",
             "--admin", f"127.0.0.1:{self.admin}", "--speed", str(self.speed), "--quiet"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        self._wait_port(self.admin, self.sim)

    def start_service(self) -> None:
        with self.log.open("ab") as err:
            self.service = subprocess.Popen(
                [*CLI, "run", "--config", str(self.config)], stdout=err, stderr=err
            )
        self._wait_port(self.api, self.service)

    @staticmethod
    def _wait_port(port: int, proc: subprocess.Popen[bytes], timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                raise RuntimeError(f"process exited with {proc.returncode} before listening")
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    return
            time.sleep(0.2)
        raise RuntimeError(f"nothing listens on port {port} after {timeout_s:g} s")

    @staticmethod
    def _kill(proc: subprocess.Popen[bytes] | None) -> None:
        if proc is not None and proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            proc.wait(10)

    def start(self) -> None:
        self.write_config()
        if subprocess.run([*CLI, "db", "upgrade", "--config", str(self.config)],
                          capture_output=True).returncode != 0:  # fmt: skip
            raise RuntimeError("plantcheck db upgrade failed")
        self.start_simulator()
        self.start_service()
        self.started_at = time.time()

    def stop(self) -> None:
        if self.service is not None and self.service.poll() is None:
            self.service.terminate()
            try:
                self.service.wait(30)
            except subprocess.TimeoutExpired:
                self._kill(self.service)
        self._kill(self.sim)

    def fault(self, kind: str) -> None:
        """Inject one fault of ``kind`` (one of ``FAULTS``)."""
        if kind == "kill-simulator":
            self._kill(self.sim)
            time.sleep(3.0)
            self.start_simulator()
        elif kind == "kill-service":
            self._kill(self.service)
            time.sleep(3.0)
            self.start_service()
        else:
            command = {"stall": "stall 8 both", "drop": "drop both", "restart": "restart 5 both"}
            asyncio.run(send_admin("127.0.0.1", self.admin, command[kind]))

    def wait_back(self, timeout_s: float = 30.0) -> dict[str, int]:
        """After a restart of both servers: per protocol, when its port listened again (µs
        since the epoch), having refused first."""
        ports = {"modbus": self.modbus, "opcua": self.opcua}
        deadline = time.monotonic() + timeout_s
        down: set[str] = set()
        back: dict[str, int] = {}
        while len(back) < len(ports) and time.monotonic() < deadline:
            for protocol, port in ports.items():
                if protocol in back:
                    continue
                with socket.socket() as s:
                    s.settimeout(0.5)
                    up = s.connect_ex(("127.0.0.1", port)) == 0
                if up and protocol in down:
                    back[protocol] = time.time_ns() // 1000
                elif not up:
                    down.add(protocol)
            time.sleep(0.02)
        if len(back) < len(ports):
            raise RuntimeError(f"servers not down and back in {timeout_s:g} s: {back}")
        return back

    def freshness_bound_s(self, watch_s: float = 6.0, floor_s: float = 5.0) -> float:
        """How old the newest stored sample may be in undisturbed flow on this machine now:
        the larger of ``floor_s`` and three times the oldest "newest sample" seen over
        ``watch_s`` (a loaded machine runs late; a test's freshness follows what it managed
        before its faults, not a fixed clock)."""
        ages = []
        t_end = time.monotonic() + watch_s
        while time.monotonic() < t_end:
            time.sleep(1.0)
            now = time.time()
            ages += [now - a.newest_us / 1e6 for a in map(self.account, LOOPS) if a.newest_us]
        return max(floor_s, 3.0 * max(ages, default=0.0))

    def return_lag_s(self, protocol: str, back_us: int) -> float | None:
        """Seconds from a server's return (``back_us``) to the first sample received from it
        after that, or None when none came."""
        with sqlite3.connect(self.db) as con:
            row = con.execute(
                "SELECT min(s.recv_us) FROM samples s JOIN tags t ON s.tag_id = t.id "
                "JOIN loops l ON t.loop_id = l.id WHERE l.name = ? AND s.recv_us >= ? "
                "AND s.value IS NOT NULL",
                (LOOPS[protocol], back_us),
            ).fetchone()
        return None if row[0] is None else (row[0] - back_us) / 1e6

    def memory_kb(self) -> int:
        return rss_kb(self.service.pid) if self.service is not None else 0

    def account(self, protocol: str) -> SampleAccount:
        """The PV history of the loop collected over ``protocol``."""
        with sqlite3.connect(self.db) as con:
            rows = con.execute(
                "SELECT s.ts_us, s.status FROM samples s JOIN tags t ON s.tag_id = t.id "
                "JOIN loops l ON t.loop_id = l.id WHERE l.name = ? AND t.signal = 'pv'",
                (LOOPS[protocol],),
            ).fetchall()
        # the simulator's PV changes once per simulated second: an OPC UA subscription reports
        # each change, the Modbus poll reads every POLL_S
        interval = POLL_S if protocol == "modbus" else max(POLL_S, 1.0 / self.speed)
        return account_samples([r[0] for r in rows], [r[1] for r in rows], interval)


@contextmanager
def drill(
    folder: Path, speed: float = 1.0, db_dir: Path | None = None, buffer_dir: Path | None = None
) -> Iterator[Drill]:
    d = Drill(folder, speed, db_dir=db_dir, buffer_dir=buffer_dir)
    try:
        d.start()
        yield d
    finally:
        d.stop()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--fault-every", type=float, default=60.0, help="seconds between faults")
    ap.add_argument("--speed", type=float, default=1.0, help="simulated seconds per second")
    args = ap.parse_args()
    with (
        tempfile.TemporaryDirectory(prefix="plantcheck-soak-") as tmp,
        drill(Path(tmp), args.speed) as d,
    ):
        time.sleep(10.0)
        mem_start = d.memory_kb()
        end = time.monotonic() + args.minutes * 60.0
        n = 0
        while time.monotonic() + args.fault_every < end:
            time.sleep(args.fault_every)
            kind = FAULTS[n % len(FAULTS)]
            print(f"{time.time() - d.started_at:7.0f} s  fault {n + 1}: {kind}", flush=True)
            d.fault(kind)
            n += 1
        time.sleep(max(0.0, end - time.monotonic()))
        mem_end = d.memory_kb()
        run_s = time.time() - d.started_at
        print(f"\n{args.minutes:g} min, {n} faults, speed {args.speed:g}")
        print("protocol  expected   stored   lost  silent holes  marked gaps  time marked")
        for protocol in LOOPS:
            a = d.account(protocol)
            interval = POLL_S if protocol == "modbus" else max(POLL_S, 1.0 / args.speed)
            expected = int(run_s / interval)
            print(
                f"{protocol:8s} {expected:9d} {a.samples:8d} {a.lost:6d} {a.silent_holes:13d} "
                f"{a.gap_markers:12d} {a.marked_s:10.0f} s"
            )
        print(f"service log: {os.path.getsize(d.log)} bytes")
        print(f"service memory (RSS with workers): {mem_start / 1024:.0f} MB at start, "
              f"{mem_end / 1024:.0f} MB at end")  # fmt: skip


if __name__ == "__main__":
    main()
