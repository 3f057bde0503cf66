"""Run the simulated plant on its clock and serve it over Modbus TCP and OPC UA.

The clock: simulated time advances by ``sample_time_s`` per step; step *k* is due at wall time
``k · sample_time_s / speed`` after the start. The runner takes every due step (catching up
in a burst when it is late), publishes each step to OPC UA (subscribers get every sample with
its simulated source timestamp) and the latest step to the Modbus register image, then sleeps
until the next step is due. ``stats.lag_s`` is how far the plant is behind its schedule; it
stays near zero while the process keeps up (``benchmarks/simulator_capacity.py``).

When OPC UA is served and the plant falls more than ``MAX_OPCUA_BURST`` steps behind, the
clock yields: the schedule moves back so that the plant runs slower than ``speed`` rather
than skip samples (``stats.yielded_s``, logged once per episode). It used to write only the
newest steps of a long burst: on a loaded machine (the demo at 100x beside two busy processes)
10-30 % of the samples never reached the subscribers, and the windows, holed and filled,
no longer showed the sticky valves' size. A plant served over Modbus alone keeps its pace:
a poller reads only the newest step anyway.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

from plantcheck.simulator.faults import ActiveFault, FaultState, serve_admin
from plantcheck.simulator.modbus_server import ModbusPlantServer
from plantcheck.simulator.opcua_server import OpcUaPlantServer
from plantcheck.simulator.plant import Plant
from plantcheck.simulator.scenario import Scenario

log = logging.getLogger("plantcheck.simulator")

MAX_OPCUA_BURST = 50
"""Steps written to OPC UA in one catch-up burst at most; later than this, the clock yields."""


@dataclass
class RunStats:
    """Clock health: current and worst lag behind schedule (s), and the wall seconds the clock
    yielded (the plant ran slower than its speed so as not to skip OPC UA samples)."""

    lag_s: float = 0.0
    max_lag_s: float = 0.0
    yielded_s: float = 0.0
    lags: list[float] = field(default_factory=list)


class PlantRunner:
    """A plant, its servers and its faults; ``run()`` until ``stop()``."""

    def __init__(self, scenario: Scenario, start: datetime | None = None) -> None:
        self.scenario = scenario
        clock = scenario.clock
        first = start or clock.start or datetime.now(UTC)
        self.warmup_steps = round(clock.warmup_s / clock.sample_time_s)
        """Steps run before serving (``clock.warmup_s``): the first sample served is at
        ``first``, the plant having run since ``warmup_s`` before it."""
        self.plant = Plant(scenario, first - timedelta(seconds=clock.warmup_s))
        self.faults = FaultState(list(scenario.fault), on_action=self._on_action)
        self.modbus = (
            ModbusPlantServer(scenario.modbus, scenario, self.faults)
            if scenario.modbus.enabled
            else None
        )
        self.opcua = (
            OpcUaPlantServer(scenario.opcua, scenario, self.faults)
            if scenario.opcua.enabled
            else None
        )
        self.stats = RunStats()
        self._stop = asyncio.Event()
        self._admin: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._opcua_stalled = False
        self._yielding = False
        self.ready = asyncio.Event()

    # -- servers -------------------------------------------------------------------------
    async def start_servers(self, which: str = "both") -> None:
        if self.modbus and which in ("modbus", "both"):
            await self.modbus.start()
            self.modbus.publish(self.plant)
        if self.opcua and which in ("opcua", "both"):
            await self.opcua.start()

    async def stop_servers(self, which: str = "both") -> None:
        if self.modbus and which in ("modbus", "both"):
            await self.modbus.stop()
        if self.opcua and which in ("opcua", "both"):
            await self.opcua.stop()

    def drop_connections(self, which: str = "both") -> None:
        if self.modbus and which in ("modbus", "both"):
            self.modbus.drop_connections()
        if self.opcua and which in ("opcua", "both"):
            self.opcua.drop_connections()

    async def _restart(self, which: str, down_s: float) -> None:
        log.warning("fault: %s server(s) down for %.1f s", which, down_s)
        await self.stop_servers(which)
        await asyncio.sleep(down_s)
        await self.start_servers(which)
        log.warning("fault: %s server(s) back", which)

    def _on_action(self, fault: ActiveFault) -> None:
        if fault.kind == "drop":
            log.warning("fault: dropping %s connections", fault.target)
            self.drop_connections(fault.target)
        elif fault.kind == "restart":
            down = max(0.0, fault.until - time.monotonic())
            task = asyncio.get_running_loop().create_task(self._restart(fault.target, down))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)

    def status(self) -> dict[str, object]:
        return {
            "time": self.plant.time.isoformat(),
            "steps": self.plant.steps - self.warmup_steps,
            "speed": self.scenario.clock.speed,
            "lag_s": round(self.stats.lag_s, 3),
            "yielded_s": round(self.stats.yielded_s, 3),
            "loops": len(self.plant.loops),
        }

    # -- clock ---------------------------------------------------------------------------
    def _steps_to_yield(self, due: int) -> int:
        """Steps by which the schedule moves back before step ``due`` is taken: those beyond
        ``MAX_OPCUA_BURST`` late while OPC UA is served (module docstring), else 0. Logs the
        start and the end of each episode once."""
        behind = due - self.plant.steps - MAX_OPCUA_BURST
        if self.opcua and behind > 0:
            if not self._yielding:
                log.warning(
                    "the plant runs slower than %gx: this machine cannot keep up; every sample "
                    "is still served (status: yielded_s)",
                    self.scenario.clock.speed,
                )
            self._yielding = True
            return behind
        if self._yielding and due - self.plant.steps <= 1:
            log.warning("the plant keeps its speed again")
            self._yielding = False
        return 0

    async def _tick(self, due: int) -> None:
        late = due - self.plant.steps
        while self.plant.steps < due:
            self.plant.step()
            self.faults.update(self.plant.t - self.scenario.clock.warmup_s)
            if self.opcua:
                await self.opcua.publish(self.plant)
        if late and self.modbus:
            self.modbus.publish(self.plant)
        if self.opcua:
            stalled = self.faults.stalled("opcua")
            if stalled != self._opcua_stalled:
                self.opcua.set_stalled(stalled)
                self._opcua_stalled = stalled

    async def run(self) -> None:
        """Serve until ``stop()``: servers, admin interface, signals, clock."""
        while self.plant.steps < self.warmup_steps:
            self.plant.step()
        await self.start_servers()
        a = self.scenario.admin
        if a.enabled:
            ids = {s.id for s in self.scenario.loop}
            self._admin = await serve_admin(
                a.host, a.port, self.faults, ids, self.status, self.plant.retune
            )
        loop = asyncio.get_running_loop()
        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
            loop.add_signal_handler(
                signal.SIGUSR1, lambda: self.faults.start(ActiveFault("drop", "both", 0.0))
            )
            loop.add_signal_handler(
                signal.SIGUSR2,
                lambda: self.faults.start(ActiveFault("restart", "both", time.monotonic() + 5)),
            )
        step_wall = self.scenario.clock.sample_time_s / self.scenario.clock.speed
        wall0 = time.monotonic()
        self.ready.set()
        try:
            while not self._stop.is_set():
                elapsed = time.monotonic() - wall0
                due = self.warmup_steps + int(elapsed / step_wall) + 1
                back = self._steps_to_yield(due)
                wall0 += back * step_wall
                self.stats.yielded_s += back * step_wall
                due -= back
                await self._tick(due)
                lag = time.monotonic() - wall0 - (due - 1 - self.warmup_steps) * step_wall
                self.stats.lag_s = lag
                self.stats.max_lag_s = max(self.stats.max_lag_s, lag)
                self.stats.lags.append(lag)
                if len(self.stats.lags) > 100_000:
                    del self.stats.lags[:50_000]
                wait = wall0 + (due - self.warmup_steps) * step_wall - time.monotonic()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._stop.wait(), max(wait, 0.0005))
        finally:
            for sig in (signal.SIGUSR1, signal.SIGUSR2):
                with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                    loop.remove_signal_handler(sig)
            if self._admin is not None:
                self._admin.close()
            for task in list(self._tasks):
                task.cancel()
            await self.stop_servers()

    def stop(self) -> None:
        self._stop.set()
