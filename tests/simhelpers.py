"""Run the simulator's real servers inside a test: free loopback ports, a running plant."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime
from typing import TypeVar

from helpers import free_port

from plantcheck.simulator.runner import PlantRunner
from plantcheck.simulator.scenario import LoopSpec, Scenario, load_scenario

T = TypeVar("T")
START = datetime(2026, 1, 1, tzinfo=UTC)


def scenario_on_free_ports(
    scenario: Scenario | None = None,
    *,
    speed: float = 1.0,
    sample_time_s: float = 1.0,
    warmup_s: float = 0.0,
    only: tuple[str, ...] = (),
    **modbus: object,
) -> Scenario:
    """The scenario (default: the bundled one) with every server on a free loopback port,
    started cold unless ``warmup_s`` says otherwise (the tests count steps from the start);
    ``only``: just these loops (a simulator in the test's own event loop serves only what the
    test reads, which a loaded machine keeps up with)."""
    sc = scenario or load_scenario()
    if only:
        sc = sc.model_copy(update={"loop": [lp for lp in sc.loop if lp.id in only]})
    clock = {"speed": speed, "sample_time_s": sample_time_s, "warmup_s": warmup_s}
    return sc.model_copy(
        update={
            "clock": sc.clock.model_copy(update=clock),
            "modbus": sc.modbus.model_copy(
                update={"host": "127.0.0.1", "port": free_port(), **modbus}
            ),
            "opcua": sc.opcua.model_copy(
                update={"url": f"opc.tcp://127.0.0.1:{free_port()}/plantcheck/"}
            ),
            "admin": sc.admin.model_copy(update={"host": "127.0.0.1", "port": free_port()}),
        }
    )


def scaled_scenario(
    n: int, *, speed: float = 1.0, modbus_port: int | None = None, opcua: bool = False
) -> Scenario:
    """``n`` copies of the default scenario's loops (ids L00000…), servers on free ports and
    no admin port: the plant of the capacity and ingest benchmarks. A loop whose load comes
    from another loop's cycle (``from_loop``) takes it from that loop's copy in its own group
    of copies, which comes before it as in the original."""
    base = load_scenario()
    index = {lp.id: k for k, lp in enumerate(base.loop)}
    m = len(base.loop)

    def copy(i: int) -> LoopSpec:
        spec = base.loop[i % m].model_dump()
        group = i - i % m
        for d in spec.get("disturbances", []):
            if d.get("from_loop"):
                d["from_loop"] = f"L{group + index[d['from_loop']]:05d}"
        return LoopSpec.model_validate({**spec, "id": f"L{i:05d}"})

    loops = [copy(i) for i in range(n)]
    sc = scenario_on_free_ports(base, speed=speed)
    return sc.model_copy(
        update={
            "loop": loops,
            "modbus": sc.modbus.model_copy(update={"port": modbus_port or free_port()}),
            "opcua": sc.opcua.model_copy(update={"enabled": opcua}),
            "admin": sc.admin.model_copy(update={"enabled": False}),
        }
    )


async def with_plant(scenario: Scenario, body: Callable[[PlantRunner], Awaitable[T]]) -> T:
    """Start the plant and its servers, run ``body(runner)``, stop everything."""
    runner = PlantRunner(scenario, start=START)
    task = asyncio.create_task(runner.run())
    ready = asyncio.create_task(runner.ready.wait())
    done, _ = await asyncio.wait({task, ready}, timeout=30, return_when=asyncio.FIRST_COMPLETED)
    if task in done:
        task.result()  # raises the start-up error
    try:
        return await body(runner)
    finally:
        runner.stop()
        await asyncio.wait_for(task, 30)


def run_with_plant(scenario: Scenario, body: Callable[[PlantRunner], Awaitable[T]]) -> T:
    return asyncio.run(with_plant(scenario, body))
