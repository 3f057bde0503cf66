"""Modbus TCP server of the simulated plant (pymodbus 3.16, ``SimDevice``/``SimData``).

Register map (the same addresses in holding registers, FC 3, and input registers, FC 4):

- 0–3: simulated time of the latest sample, float64 seconds since 1970-01-01 UTC;
- 4–5: step counter, uint32; 6–9 reserved (0);
- loop *i* (0-based, scenario order) from ``10 + 10·i``: SP, PV, OP, MV, Mode, each a float32
  in two registers (PV/SP in engineering units, OP/MV in % of travel, Mode 1 auto / 0 manual,
  MV NaN when the loop has no positioner feedback).

Word order (``big`` = high word first) and byte order (``little`` = bytes swapped within each
register) follow the scenario's ``[modbus]`` table. All registers are read-only: writes are
refused with exception 2 (the simulator is a plant that plantcheck only reads).
"""

from __future__ import annotations

import asyncio
import math

import numpy as np
from numpy.typing import NDArray
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from plantcheck.connectors.modbus_codec import encode
from plantcheck.simulator.export import loop_base
from plantcheck.simulator.faults import FaultState
from plantcheck.simulator.plant import Plant
from plantcheck.simulator.scenario import (
    HEADER_REGISTERS,
    REGISTERS_PER_LOOP,
    SIGNALS,
    ModbusSpec,
    Scenario,
)


class ModbusPlantServer:
    """Serves a ``Plant`` over Modbus TCP; ``publish`` refreshes the register image."""

    def __init__(self, spec: ModbusSpec, scenario: Scenario, faults: FaultState) -> None:
        self.spec = spec
        self.scenario = scenario
        self.faults = faults
        self.n_registers = HEADER_REGISTERS + REGISTERS_PER_LOOP * len(scenario.loop)
        self.image: list[int] = [0] * self.n_registers
        self.server: ModbusTcpServer | None = None
        self._ids = [s.id for s in scenario.loop]

    def _device(self) -> SimDevice:
        block = SimData(
            address=0,
            count=self.n_registers,
            values=0,
            datatype=DataType.REGISTERS,
            readonly=True,
        )
        return SimDevice(id=self.spec.device_id, simdata=[block], action=self._action)

    async def _action(
        self,
        func_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """Called by pymodbus for every request: apply faults, then copy the current image."""
        while self.faults.stalled("modbus"):
            await asyncio.sleep(0.05)
        code = self.faults.exception_code("modbus")
        if code is not None:
            return ExcCodes(code)
        if values:  # writes never reach here (read-only), but never accept one
            return ExcCodes.ILLEGAL_ADDRESS
        off = address - start_address
        registers[off : off + count] = self.image[off : off + count]
        return None

    async def start(self) -> None:
        """Listen on the scenario's address; OSError naming it where that fails (pymodbus
        raises a bare RuntimeError, "Could not start listen", for a port already taken)."""
        server = ModbusTcpServer(self._device(), address=(self.spec.host, self.spec.port))
        try:
            await server.serve_forever(background=True)
        except RuntimeError as exc:
            raise OSError(
                f"the Modbus TCP server cannot listen on {self.spec.host}:{self.spec.port}, "
                f"address already in use or not this machine's ({exc})"
            ) from exc
        self.server = server

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.shutdown()  # type: ignore[no-untyped-call]
            self.server = None

    def drop_connections(self) -> None:
        """Close every client connection."""
        if self.server is None:
            return
        for conn in list(self.server.active_connections.values()):
            conn.close()

    def encode_values(self, values: NDArray[np.float64]) -> NDArray[np.uint16]:
        """Registers of all loops' (SP, PV, OP, MV, Mode) rows, in map order."""
        return encode(values.reshape(-1), "float32", self.spec.word_order, self.spec.byte_order)

    def publish(self, plant: Plant) -> None:
        """Refresh the register image from the plant's latest sample (NaN faults applied)."""
        values = plant.values
        if self.faults.active:
            values = values.copy()
            for i, loop_id in enumerate(self._ids):
                for j, sig in enumerate(SIGNALS):
                    if self.faults.masked("nan", "modbus", loop_id, sig) or self.faults.masked(
                        "bad", "modbus", loop_id, sig
                    ):
                        values[i, j] = math.nan
        wo, bo = self.spec.word_order, self.spec.byte_order
        header = np.zeros(HEADER_REGISTERS, dtype=np.uint16)
        header[0:4] = encode([plant.time.timestamp()], "float64", wo, bo)
        header[4:6] = encode([plant.steps], "uint32", wo, bo)
        regs = np.concatenate([header, self.encode_values(values)])
        self.image = regs.tolist()
        assert len(self.image) == loop_base(len(self._ids))
