"""Shared test helpers: running the real ``plantcheck`` command in a subprocess."""

from __future__ import annotations

import contextlib
import fcntl
import itertools
import json
import os
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pgcluster
import pytest
from helpers import ComputedOnce, RunCli
from pgcluster import PgCluster
from servicehelpers import Service, SharedService

from plantcheck.storage.database import upgrade

ROOT = Path(__file__).resolve().parents[1]


def _root_entries() -> set[str]:
    """What the repository root holds, but caches (``.pytest_cache``, ``__pycache__``: the
    root is the package's folder)."""
    return {
        p.name for p in ROOT.iterdir() if not p.name.startswith(".") and p.name != "__pycache__"
    }


SHARED_SERVICE_MINUTES = 1.5
"""What building the session's ``service`` fixture takes on a loaded machine (imported
records, a service started, every loop diagnosed): once per worker that runs a test using it."""


def _minutes(item: pytest.Item) -> float:
    """A slow test's expected minutes on a loaded run (``slow(minutes=...)``, default 1); 0 for
    the others."""
    mark = item.get_closest_marker("slow")
    return float(mark.kwargs.get("minutes", 1.0)) if mark is not None else 0.0


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The tests marked slow (real processes, fault drills, simulated plants filling their
    windows; 1-5 minutes each on a loaded machine) start first, the longest first, spread
    over the workers by their minutes; the tests that use the session's running ``service``
    go together to one worker, which builds it once.

    Collected in file order, the fault suite began at 95 % of a loaded run and was the last
    to finish (issue 47's 12 minutes). pytest-xdist's ``worksteal`` hands each worker one
    contiguous share of this order, and a worker steals only from the end of another's: with
    every slow test at the front they all fell to the first worker, one after another, and
    the service was built by three workers. Each share now begins with its own slow tests."""
    workers = int(getattr(config, "workerinput", {}).get("workercount", 1))
    shared = [item for item in items if "service" in getattr(item, "fixturenames", ())]
    units = [[item] for item in items if _minutes(item) > 0 and item not in shared]
    if shared:
        units.append(shared)

    def weight(unit: list[pytest.Item]) -> float:
        return sum(map(_minutes, unit)) + (SHARED_SERVICE_MINUTES if unit is shared else 0.0)

    units.sort(key=weight, reverse=True)  # stable: equal minutes keep the file order
    heads: list[list[pytest.Item]] = [[] for _ in range(workers)]
    load = [0.0] * workers
    for unit in units:  # the longest first, each to the least loaded worker
        k = load.index(min(load))
        heads[k] += unit
        load[k] += weight(unit)
    placed = {id(item) for head in heads for item in head}
    quick = iter(item for item in items if id(item) not in placed)
    ordered: list[pytest.Item] = []
    left = len(items)
    for k, head in enumerate(heads):
        share = left // (workers - k)  # worksteal's first hand-out: pending // idle workers
        ordered += head + list(itertools.islice(quick, max(0, share - len(head))))
        left -= share
    items[:] = ordered + list(quick)


def pytest_sessionstart(session: pytest.Session) -> None:
    session.config.stash[ROOT_BEFORE] = _root_entries()


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """A test that leaves a file in the repository root (a database, a buffer written to the
    working folder) fails the run, naming it (issue 47)."""
    shared = session.config.stash.get(SHARED_SERVICE, None)
    if shared is not None:  # a run stopped before its last test's teardown
        shared.stop()
    before = session.config.stash.get(ROOT_BEFORE, None)
    if before is None:
        return
    left = sorted(_root_entries() - before)
    if left:
        print(f"\ntests left these in the repository root: {', '.join(left)}")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


ROOT_BEFORE = pytest.StashKey[set[str]]()

HEARTBEAT_S = float(os.environ.get("PLANTCHECK_TEST_HEARTBEAT_S", "20"))
"""A test running longer than this says so, and again every as long (issue 47: silent stretches
of minutes in `make test` looked like a hang; progress is due every 30 s, and at 30 a test that
began just after the last line left a 30-s silence on a loaded machine)."""


def _terminal_fd(config: pytest.Config) -> int | None:
    """The terminal's file descriptor as it was before pytest captured fd 1 (a test's output
    goes to a file meanwhile); written to with one ``os.write``, which needs no capture state
    to change from the heartbeat's thread. None where pytest does not capture at the fd."""
    capman = config.pluginmanager.get_plugin("capturemanager")
    # an xdist worker's fd 1 is its channel to the controller; its fd 2 is the controller's
    stream = "err" if hasattr(config, "workerinput") else "out"
    out = getattr(getattr(capman, "_global_capturing", None), stream, None)
    fd = getattr(out, "targetfd_save", None)
    return fd if isinstance(fd, int) else None


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    done = threading.Event()
    t0 = time.monotonic()
    terminal = _terminal_fd(item.config)

    def beat() -> None:
        while not done.wait(HEARTBEAT_S) and terminal is not None:
            line = f"\n[{item.nodeid} still running after {time.monotonic() - t0:.0f} s]\n"
            with contextlib.suppress(OSError):
                os.write(terminal, line.encode())

    thread = threading.Thread(target=beat, daemon=True)
    thread.start()
    try:
        return (yield)
    finally:
        done.set()


@pytest.fixture(scope="session")
def computed_once(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> ComputedOnce:
    """``once(name, compute)``: ``compute()``'s JSON value, computed by one pytest-xdist worker
    for the whole run and read by the others (the pattern of pytest-xdist's docs, with a file
    lock). A module fixture is built again on every worker that runs one of its tests: the
    generated cases' confusion matrix was computed twice per run, 120 s of two busy cores."""
    base = tmp_path_factory.getbasetemp()
    # a worker's folder is <run>/popen-gwN: <run> is this run's alone (the single-process
    # base's parent holds every earlier run's, where a stale value would be read)
    shared = base.parent if hasattr(request.config, "workerinput") else base

    def once(name: str, compute: Callable[[], Any]) -> Any:
        path = shared / f"{name}.json"
        with (shared / f"{name}.lock").open("w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if path.exists():
                return json.loads(path.read_text(encoding="utf-8"))
            value = compute()
            path.write_text(json.dumps(value), encoding="utf-8")
            return value

    return once


@pytest.fixture
def run_cli() -> RunCli:
    """Run ``plantcheck ARGS`` as a user would (new process), return the completed process."""

    def _run(*args: str, timeout: float = 600.0) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "plantcheck.service.cli", *args],
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )

    return _run


@pytest.fixture
def repo_root() -> Path:
    return Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def pg_cluster() -> Iterator[PgCluster]:
    """A PostgreSQL cluster for the whole session (skipped, with the reason, where impossible)."""
    reason = pgcluster.available()
    if reason:
        pytest.skip(reason)
    cluster = PgCluster()
    cluster.start()
    try:
        yield cluster
    finally:
        cluster.destroy()


SHARED_SERVICE = pytest.StashKey[SharedService]()


@pytest.fixture
def service(request: pytest.FixtureRequest) -> Service:
    """One running service over 1 h of the default plant (11 loops), every loop diagnosed,
    shared by the tests that run one after another (``SharedService``)."""
    return request.config.stash.setdefault(SHARED_SERVICE, SharedService()).get()


def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> None:
    shared = item.config.stash.get(SHARED_SERVICE, None)
    if shared is not None:
        shared.stop_unless_needed(getattr(nextitem, "fixturenames", None))


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """A fresh, migrated database of each kind (SQLite file; a new PostgreSQL database)."""
    if request.param == "sqlite":
        url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    else:
        cluster: PgCluster = request.getfixturevalue("pg_cluster")
        url = cluster.create_database(f"t{uuid.uuid4().hex[:12]}")
    upgrade(url)
    yield url
