"""Ingestion from the simulator's real servers into real databases: Modbus polling and OPC UA
subscriptions, a simulator killed and restarted, NaN and Bad status, a PostgreSQL outage."""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

import pytest
from pgcluster import PgCluster
from simhelpers import scenario_on_free_ports

from plantcheck.core.status_codes import (
    BAD_DATA_ENCODING_INVALID,
    BAD_NO_COMMUNICATION,
    BAD_SENSOR_FAILURE,
    is_bad,
)
from plantcheck.service.config import Config, LoopConfig, SourceConfig, StorageConfig
from plantcheck.service.ingest import Ingestion
from plantcheck.simulator.faults import send_admin
from plantcheck.simulator.runner import PlantRunner
from plantcheck.simulator.scenario import Scenario
from plantcheck.storage.database import upgrade

LOOPS = ("FIC101", "FIC102", "FIC701")


def _config(sc: Scenario, url: str, buffer: Path, protocol: str) -> Config:
    if protocol == "modbus":
        src = SourceConfig(name="sim", protocol="modbus", port=sc.modbus.port, poll_interval_s=0.2,
                           timeout_s=0.5)  # fmt: skip
    else:
        src = SourceConfig(name="sim", protocol="opcua", url=sc.opcua.url, poll_interval_s=0.1)
    loops = []
    for i, spec in enumerate(sc.loop):
        if spec.id not in LOOPS:
            continue
        if protocol == "modbus":
            base = 10 + 10 * i
            tags = {s: f"hr:{base + 2 * j}:float32" for j, s in enumerate(("sp", "pv", "op"))}
        else:
            tags = {s: f"ns=2;s={spec.id}.{s.upper()}" for s in ("sp", "pv", "op")}
        loops.append(LoopConfig(id=spec.id, type=spec.type, source="sim", **tags))
    return Config(
        storage=StorageConfig(url=url, buffer_path=str(buffer), commit_interval_s=0.2),
        source=[src],
        loop=loops,
    )


async def _start_plant(sc: Scenario) -> tuple[PlantRunner, asyncio.Task[None]]:
    runner = PlantRunner(sc)
    task = asyncio.create_task(runner.run())
    await asyncio.wait_for(runner.ready.wait(), 30)
    return runner, task


async def _stop_plant(runner: PlantRunner, task: asyncio.Task[None]) -> None:
    runner.stop()
    await asyncio.wait_for(task, 30)


async def _rows(
    ing: Ingestion, loop: str, signal: str
) -> list[tuple[str, int, int, float | None, int]]:
    await ing.writer.flush()
    lp = (await ing.store.loops())[loop]
    return await ing.store.read_samples(lp, signals=[signal])


Row = tuple[str, int, int, float | None, int]


async def _rows_until(
    ing: Ingestion, loop: str, signal: str, done: Callable[[list[Row]], bool], timeout_s: float = 30
) -> list[Row]:
    """The stored rows once ``done(rows)`` holds (checked every 0.2 s; fails after
    ``timeout_s``): a connector's reconnection back-off has no fixed duration."""
    deadline = asyncio.get_running_loop().time() + timeout_s
    while True:
        rows = await _rows(ing, loop, signal)
        if done(rows):
            return rows
        assert asyncio.get_running_loop().time() < deadline, f"{loop}.{signal}: {rows[-5:]}"
        await asyncio.sleep(0.2)


def _after_gap(rows: list[Row]) -> list[Row]:
    """Good rows after the first gap marker (none before one is stored)."""
    gaps = [r[1] for r in rows if r[4] == BAD_NO_COMMUNICATION]
    return [r for r in rows if gaps and r[1] > gaps[0] and not is_bad(r[4])]


Body = Callable[[Ingestion, PlantRunner, asyncio.Task[None]], Awaitable[None]]


def _run(url: str, sc: Scenario, tmp: Path, protocol: str, body: Body) -> None:
    async def main() -> None:
        runner, task = await _start_plant(sc)
        ing = await Ingestion.start(_config(sc, url, tmp / "buffer.db", protocol))
        try:
            await body(ing, runner, task)
        finally:
            await ing.stop()
            if not task.done():
                await _stop_plant(runner, task)

    asyncio.run(main())


def test_modbus_ingest_survives_a_simulator_restart_and_stores_nan_as_bad(
    tmp_path: Path,
) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    sc = scenario_on_free_ports(speed=5.0)
    sc = sc.model_copy(update={"opcua": sc.opcua.model_copy(update={"enabled": False})})

    async def body(ing: Ingestion, runner: PlantRunner, task: asyncio.Task[None]) -> None:
        before = await _rows_until(ing, "FIC101", "pv", lambda rows: len(rows) >= 5)
        assert all(r[3] is not None and r[4] == 0 for r in before)
        # a NaN from the device is stored as Bad with no value, never as a number
        await send_admin("127.0.0.1", sc.admin.port, "nan 1 FIC101 PV")
        await asyncio.sleep(1.0)
        rows = await _rows(ing, "FIC101", "pv")
        nan_rows = [r for r in rows if r[4] == BAD_DATA_ENCODING_INVALID]
        assert nan_rows and all(r[3] is None for r in nan_rows)
        (up,) = ing.source_health()
        assert (up.name, up.protocol, up.state) == ("sim", "modbus", "up") and up.since_us
        # kill the simulator: no crash, a gap marker; restart it: data again
        await _stop_plant(runner, task)
        await asyncio.sleep(1.5)
        (down,) = ing.source_health()
        assert down.state == "down" and down.failures >= 1 and down.last_error, down
        assert down.last_good_sample_us is not None and down.since_us > down.last_good_sample_us
        # down past its grace period (60 s by default): not ready
        assert ing.sources_down_past_grace(down.since_us + 30_000_000) == []
        assert ing.sources_down_past_grace(down.since_us + 61_000_000) == ["sim"]
        runner2, task2 = await _start_plant(sc)
        try:
            # the connector retries with back-off (0.5 s doubling, jittered): wait for its data
            rows = await _rows_until(ing, "FIC101", "pv", lambda rows: len(_after_gap(rows)) >= 5)
            gaps = [r for r in rows if r[4] == BAD_NO_COMMUNICATION]
            assert len(gaps) == 1 and gaps[0][3] is None
            assert ing.connectors[0].state.connected
            assert ing.source_health()[0].state == "up"
            # SP is held: stored when it changes and again after the gap, never repeated
            sp = await _rows_until(ing, "FIC101", "sp", lambda rows: not is_bad(rows[-1][4]))
            assert all((a[3], a[4]) != (b[3], b[4]) for a, b in itertools.pairwise(sp))
            assert [r[4] for r in sp].count(BAD_NO_COMMUNICATION) == 1
            assert len(sp) < len(rows) / 3
        finally:
            await _stop_plant(runner2, task2)

    _run(url, sc, tmp_path, "modbus", body)


def test_opcua_subscription_stores_simulated_timestamps_and_bad_status(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    # the simulator shares this test's event loop: serving all eleven loops at 10x under a
    # loaded run, it answered the admin command late (a time-out)
    sc = scenario_on_free_ports(speed=10.0, only=("FIC101", "FIC102"))

    async def body(ing: Ingestion, runner: PlantRunner, task: asyncio.Task[None]) -> None:
        await asyncio.sleep(2.5)
        rows = await _rows(ing, "FIC102", "pv")
        good = [r for r in rows if not is_bad(r[4])]
        assert len(good) >= 10
        steps = {b[1] - a[1] for a, b in itertools.pairwise(good)}
        assert steps == {1_000_000}  # every simulated second, none lost or repeated
        await send_admin("127.0.0.1", sc.admin.port, "bad 1 FIC102 PV")
        await asyncio.sleep(1.5)
        rows = await _rows(ing, "FIC102", "pv")
        bad = [r for r in rows if r[4] == BAD_SENSOR_FAILURE]
        assert bad and all(r[3] is None for r in bad)

    _run(url, sc, tmp_path, "opcua", body)


@pytest.mark.slow
def test_postgresql_outage_loses_no_sample(pg_cluster: PgCluster, tmp_path: Path) -> None:
    upgrade(pg_cluster.url)
    sc = scenario_on_free_ports(speed=5.0)
    sc = sc.model_copy(update={"opcua": sc.opcua.model_copy(update={"enabled": False})})

    async def body(ing: Ingestion, runner: PlantRunner, task: asyncio.Task[None]) -> None:
        tag_ids = [t for lp in (await ing.store.loops()).values() for t in lp.tags.values()]
        start = await ing.store.count_samples(tag_ids)
        await asyncio.sleep(2.0)
        await asyncio.to_thread(pg_cluster.stop)
        await asyncio.sleep(30.0)
        assert not ing.writer.stats.store_up and len(ing.writer.buffer) > 0
        await asyncio.to_thread(pg_cluster.start)
        await asyncio.sleep(1.0)
        for c in ing.connectors:
            c.stop()
        await asyncio.gather(*ing.tasks)
        for _ in range(60):
            await ing.writer.flush()
            if ing.writer.depth == 0 and ing.writer.stats.store_up:
                break
            await asyncio.sleep(0.5)
        stored = await ing.store.count_samples(tag_ids) - start
        assert ing.writer.dropped == 0
        assert stored == ing.writer.stats.received  # every sample is there, once

    _run(pg_cluster.url, sc, tmp_path, "modbus", body)


STALL_S = 15.0


@pytest.mark.slow
@pytest.mark.parametrize("speed", [1.0, 5.0])
def test_opcua_ingest_resumes_after_a_server_stall(tmp_path: Path, speed: float) -> None:
    """Issue 27: after a 15-s stall asyncua's auto-reconnect could restore no subscription and
    stay silent for good. The connector owns its session and watches the data: a gap marker
    covers the stall and samples flow again."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    sc = scenario_on_free_ports(speed=speed)
    sc = sc.model_copy(update={"modbus": sc.modbus.model_copy(update={"enabled": False})})

    async def body(ing: Ingestion, runner: PlantRunner, task: asyncio.Task[None]) -> None:
        await _rows_until(ing, "FIC102", "pv", lambda rows: len(rows) >= 5)
        answer = await send_admin("127.0.0.1", sc.admin.port, f"stall {STALL_S:g} opcua")
        assert "stall" in answer, answer
        await asyncio.sleep(STALL_S)
        rows = await _rows_until(
            ing, "FIC102", "pv", lambda rows: len(_after_gap(rows)) >= 10, timeout_s=60
        )
        assert any(r[4] == BAD_NO_COMMUNICATION for r in rows)
        source = ing.connectors[0]
        assert source.state.connected and source.state.failing_since_us is None

    _run(url, sc, tmp_path, "opcua", body)


@pytest.mark.slow
def test_a_stalled_modbus_device_is_logged_once_and_backs_off(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Issue 27: a device that accepts TCP but does not answer logged 'unavailable'/'back'
    every 2.5 s (the back-off reset on connect). Back counts at the first data: one failure
    line, one recovery line, a gap marker, and samples again after the stall."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    sc = scenario_on_free_ports(speed=5.0)
    sc = sc.model_copy(update={"opcua": sc.opcua.model_copy(update={"enabled": False})})
    caplog.set_level("INFO", logger="plantcheck.connectors")

    async def body(ing: Ingestion, runner: PlantRunner, task: asyncio.Task[None]) -> None:
        await _rows_until(ing, "FIC102", "pv", lambda rows: len(rows) >= 5)
        await send_admin("127.0.0.1", sc.admin.port, "stall 12 modbus")
        await asyncio.sleep(12.0)
        await _rows_until(ing, "FIC102", "pv", lambda rows: len(_after_gap(rows)) >= 5, 60)
        messages = [r.getMessage() for r in caplog.records if r.name == "plantcheck.connectors"]
        assert sum("unavailable" in m for m in messages) == 1, messages
        assert sum("back after" in m for m in messages) == 1, messages
        assert ing.connectors[0].state.failures >= 2  # it kept trying, further apart

    _run(url, sc, tmp_path, "modbus", body)


@pytest.mark.parametrize("clock", ["", "hr:0:float64"])
def test_a_modbus_clock_register_stamps_plant_time(tmp_path: Path, clock: str) -> None:
    """Issue 47: Modbus has no source time; an accelerated plant polled without a clock is
    stamped with wall time (its periods read 20 times too short). With the simulator's clock
    register (plant time, registers 0-3) the stored times advance as the plant does."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    speed = 20.0
    sc = scenario_on_free_ports(speed=speed)
    sc = sc.model_copy(update={"opcua": sc.opcua.model_copy(update={"enabled": False})})
    cfg = _config(sc, url, tmp_path / "buffer.db", "modbus")
    cfg.source[0] = cfg.source[0].model_copy(update={"clock": clock})

    async def main() -> None:
        runner, task = await _start_plant(sc)
        ing = await Ingestion.start(cfg)
        try:
            first = await _rows_until(ing, "FIC101", "pv", lambda rows: len(rows) >= 3)
            t_wall = time.monotonic()
            await asyncio.sleep(4.0)
            rows = await _rows(ing, "FIC101", "pv")
            wall_s = time.monotonic() - t_wall
        finally:
            await ing.stop()
            await _stop_plant(runner, task)
        good = [r for r in rows if r[4] == 0]
        span_s = (good[-1][1] - first[-1][1]) / 1e6
        if clock:  # plant time: about 20 s per second
            assert span_s > 0.6 * speed * wall_s, (span_s, wall_s)
            # one sample per simulated second: a value polled twice is stored once
            assert len({r[1] for r in good}) == len(good)
        else:  # wall time
            assert span_s < 1.5 * wall_s, (span_s, wall_s)

    asyncio.run(main())
