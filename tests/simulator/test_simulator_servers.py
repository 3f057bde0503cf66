"""The simulator's servers with real clients: pymodbus reads and decodes the whole register map,
asyncua subscribes and receives data changes; faults on demand reach the clients."""

from __future__ import annotations

import asyncio
import math
from datetime import timedelta
from typing import Any

import numpy as np
import pytest
from asyncua import Client, ua
from pymodbus.client import AsyncModbusTcpClient
from simhelpers import START, run_with_plant, scenario_on_free_ports

from plantcheck.connectors.modbus_codec import decode
from plantcheck.simulator.export import register_map
from plantcheck.simulator.faults import send_admin
from plantcheck.simulator.runner import PlantRunner
from plantcheck.simulator.scenario import SIGNALS


async def _read_map(client: AsyncModbusTcpClient, n: int, fc: int = 3) -> list[int]:
    regs: list[int] = []
    read = client.read_holding_registers if fc == 3 else client.read_input_registers
    for a in range(0, n, 100):
        r = await read(a, count=min(100, n - a), device_id=1)
        assert not r.isError(), r
        regs += r.registers
    return regs


@pytest.mark.parametrize(
    ("word_order", "byte_order"), [("big", "big"), ("little", "big"), ("little", "little")]
)
def test_modbus_client_reads_and_decodes_every_register(word_order: str, byte_order: str) -> None:
    # one step per minute of wall time: the plant holds still while the test reads
    sc = scenario_on_free_ports(
        speed=1.0, sample_time_s=60.0, word_order=word_order, byte_order=byte_order
    )
    sc = sc.model_copy(update={"opcua": sc.opcua.model_copy(update={"enabled": False})})

    async def body(runner: PlantRunner) -> None:
        client = AsyncModbusTcpClient("127.0.0.1", port=sc.modbus.port)
        assert await client.connect()
        try:
            assert runner.modbus is not None
            n = runner.modbus.n_registers
            for fc in (3, 4):
                regs = await _read_map(client, n, fc)
                t = decode(regs[0:4], "float64", word_order, byte_order)[0]  # type: ignore[arg-type]
                assert t == pytest.approx(START.timestamp())
                steps = decode(regs[4:6], "uint32", word_order, byte_order)[0]  # type: ignore[arg-type]
                assert steps == runner.plant.steps == 1
                for e in register_map(sc):
                    value = decode(
                        regs[e.address : e.address + 2], "float32", word_order, byte_order
                    )[0]  # type: ignore[arg-type]
                    i = runner.plant.index[e.loop]
                    truth = runner.plant.values[i, SIGNALS.index(e.signal)]
                    if math.isnan(truth):
                        assert math.isnan(value) and e.signal == "MV"
                    else:
                        assert value == pytest.approx(truth, rel=1e-6, abs=1e-5), e
            # read-only plant: a write is refused and changes nothing
            w = await client.write_register(10, 1234, device_id=1)
            assert w.isError()
            again = await _read_map(client, 12)
            assert again[10:12] == (await _read_map(client, 12))[10:12]
        finally:
            client.close()

    run_with_plant(sc, body)


async def _subscribe(
    client: Client, node: ua.NodeId, received: list[ua.DataValue], queue: int
) -> Any:
    """A subscription (50 ms publishing) that appends every data change of ``node`` to
    ``received``, with a server queue of ``queue`` samples."""

    class Handler:
        def datachange_notification(self, node: object, val: object, data: object) -> None:
            received.append(data.monitored_item.Value)  # type: ignore[attr-defined]

    sub = await client.create_subscription(50, Handler())
    item = ua.MonitoredItemCreateRequest(
        ItemToMonitor=ua.ReadValueId(NodeId=node, AttributeId=ua.AttributeIds.Value),
        MonitoringMode=ua.MonitoringMode.Reporting,
        RequestedParameters=ua.MonitoringParameters(SamplingInterval=0, QueueSize=queue),
    )
    await sub.create_monitored_items([item])
    return sub


def test_opcua_subscription_receives_every_simulated_sample() -> None:
    sc = scenario_on_free_ports(speed=20.0)

    async def body(runner: PlantRunner) -> None:
        received: list[ua.DataValue] = []
        async with Client(sc.opcua.url, timeout=5) as client:
            idx = await client.get_namespace_index("urn:plantcheck:simulator")
            pv = client.get_node(ua.NodeId("FIC102.PV", idx))
            browsed = await client.nodes.objects.get_child([f"{idx}:FIC102", f"{idx}:PV"])
            assert browsed.nodeid == pv.nodeid
            eu = await (await pv.get_child(f"{idx}:EngineeringUnits")).read_value()
            assert eu.DisplayName.Text == "m3/h"
            sub = await _subscribe(client, pv.nodeid, received, 100)
            await asyncio.sleep(2.0)
            # MV is only there for loops with a positioner feedback
            assert await client.get_node(ua.NodeId("FIC701.MV", idx)).read_value() >= 0
            with pytest.raises(ua.UaStatusCodeError):
                await client.get_node(ua.NodeId("FIC102.MV", idx)).read_value()
            await sub.delete()
        assert len(received) >= 20
        stamps = [dv.SourceTimestamp for dv in received[1:]]
        steps = np.diff([s.timestamp() for s in stamps])
        assert np.all(np.isclose(steps, sc.clock.sample_time_s))  # no sample lost or repeated
        assert stamps[0] >= START and stamps[-1] <= runner.plant.time
        assert all(dv.StatusCode.is_good() for dv in received)
        assert all(0 < float(dv.Value.Value) < 100 for dv in received)

    run_with_plant(sc, body)


def test_a_plant_too_fast_for_the_machine_slows_down_and_skips_no_sample() -> None:
    """At a speed no machine keeps up with, the clock yields rather than write only the newest
    steps of each catch-up burst: the subscriber still gets every sample (the demo at 100x on
    a loaded machine lost 10-30 % of them that way)."""
    sc = scenario_on_free_ports(speed=100_000.0, only=("FIC102",))

    async def body(runner: PlantRunner) -> None:
        received: list[ua.DataValue] = []
        async with Client(sc.opcua.url, timeout=10) as client:
            idx = await client.get_namespace_index("urn:plantcheck:simulator")
            sub = await _subscribe(client, ua.NodeId("FIC102.PV", idx), received, 10_000)
            await asyncio.sleep(2.0)
            await sub.delete()
        assert runner.stats.yielded_s > 0, runner.status()
        assert len(received) >= 100
        steps = np.diff([dv.SourceTimestamp.timestamp() for dv in received[1:]])
        assert np.all(np.isclose(steps, sc.clock.sample_time_s)), np.unique(steps)

    run_with_plant(sc, body)


def test_faults_reach_the_clients() -> None:
    sc = scenario_on_free_ports(speed=5.0)

    async def body(runner: PlantRunner) -> None:
        admin = ("127.0.0.1", sc.admin.port)
        client = AsyncModbusTcpClient("127.0.0.1", port=sc.modbus.port, timeout=1, retries=0)
        assert await client.connect()
        # exception codes
        assert await send_admin(*admin, "exception 4 1.5") == "ok exception"
        r = await client.read_holding_registers(10, count=10, device_id=1)
        assert r.isError() and r.exception_code == 4
        await send_admin(*admin, "clear")
        assert not (await client.read_holding_registers(10, count=10, device_id=1)).isError()
        # NaN on one loop's PV (Modbus) and Bad status (OPC UA)
        assert await send_admin(*admin, "nan 3 FIC101 PV") == "ok nan"
        await asyncio.sleep(0.5)
        r = await client.read_holding_registers(10, count=10, device_id=1)
        values = decode(r.registers, "float32")
        assert math.isnan(values[1]) and not math.isnan(values[0])
        assert await send_admin(*admin, "bad 3 FIC101 PV") == "ok bad"
        async with Client(sc.opcua.url, timeout=5) as ua_client:
            idx = await ua_client.get_namespace_index("urn:plantcheck:simulator")
            await asyncio.sleep(0.5)
            dv = await ua_client.get_node(ua.NodeId("FIC101.PV", idx)).read_data_value(
                raise_on_bad_status=False
            )
            assert dv.StatusCode.is_bad()
        await send_admin(*admin, "clear")
        # stall: requests go unanswered, then answered again
        await send_admin(*admin, "stall 2 modbus")
        r_or_exc: object
        try:
            r_or_exc = await client.read_holding_registers(10, count=2, device_id=1)
        except Exception as exc:  # a time-out is what a stalled device gives
            r_or_exc = exc
        assert not hasattr(r_or_exc, "registers") or r_or_exc.isError()  # type: ignore[attr-defined]
        client.close()
        await asyncio.sleep(2.0)
        # drop: the connection is closed by the server; a new one works
        reader, writer = await asyncio.open_connection("127.0.0.1", sc.modbus.port)
        await asyncio.sleep(0.2)
        assert await send_admin(*admin, "drop") == "ok drop"
        assert await asyncio.wait_for(reader.read(100), 2) == b""  # closed by the server
        writer.close()
        # restart: the port is closed for a while, then serves again
        assert await send_admin(*admin, "restart 1.5 modbus") == "ok restart"
        await asyncio.sleep(0.5)
        down = AsyncModbusTcpClient("127.0.0.1", port=sc.modbus.port, timeout=0.5, retries=0)
        assert not await down.connect()
        down.close()
        await asyncio.sleep(2.0)
        up = AsyncModbusTcpClient("127.0.0.1", port=sc.modbus.port, timeout=1, retries=0)
        assert await up.connect()
        assert not (await up.read_holding_registers(0, count=6, device_id=1)).isError()
        up.close()
        assert (await send_admin(*admin, "stall ten")).startswith("error: expected a number")
        status = await send_admin(*admin, "status")
        assert '"steps"' in status

    run_with_plant(sc, body)


def test_scheduled_fault_from_the_scenario() -> None:
    from plantcheck.simulator.scenario import FaultSpec

    sc = scenario_on_free_ports(speed=10.0)
    sc = sc.model_copy(
        update={
            "fault": [FaultSpec(kind="exception", at_s=5, duration_s=30, code=6)],
            "opcua": sc.opcua.model_copy(update={"enabled": False}),
        }
    )

    async def body(runner: PlantRunner) -> None:
        client = AsyncModbusTcpClient("127.0.0.1", port=sc.modbus.port, timeout=1, retries=0)
        assert await client.connect()
        assert not (await client.read_holding_registers(0, count=6, device_id=1)).isError()
        while runner.plant.time < START + timedelta(seconds=6):
            await asyncio.sleep(0.05)
        r = await client.read_holding_registers(0, count=6, device_id=1)
        assert r.isError() and r.exception_code == 6
        client.close()

    run_with_plant(sc, body)


def test_a_loop_is_retuned_at_run_time_and_by_its_schedule() -> None:
    """Issue 48: a proposal is applied with the admin ``tune`` command (or the scenario's
    ``controller_schedule``) and the loop runs on with the new PI from the next sample."""
    sc = scenario_on_free_ports(speed=20.0)
    loops = list(sc.loop)
    loops[0] = loops[0].model_copy(update={"controller_schedule": [(3.0, 0.3, 4.0)]})
    sc = sc.model_copy(
        update={"loop": loops, "opcua": sc.opcua.model_copy(update={"enabled": False})}
    )

    async def body(runner: PlantRunner) -> None:
        admin = ("127.0.0.1", sc.admin.port)
        pic = runner.plant.loops[runner.plant.index["PIC301"]].loop
        assert (pic.cfg.controller.Kc, pic.cfg.controller.Ti_s) == (3.25, 8.0)
        reply = await send_admin(*admin, "tune PIC301 1.2 9.5")
        assert reply == "ok tune PIC301 Kc=1.2 Ti_s=9.5"
        assert (pic.cfg.controller.Kc, pic.cfg.controller.Ti_s) == (1.2, 9.5)
        assert (await send_admin(*admin, "tune PIC301 0 9")).startswith("error: KC must be")
        assert (await send_admin(*admin, "tune XIC9 1 9")).startswith("error: unknown loop")
        fic = runner.plant.loops[0].loop
        while runner.plant.t < 4.0:
            await asyncio.sleep(0.05)
        assert (fic.cfg.controller.Kc, fic.cfg.controller.Ti_s) == (0.3, 4.0)

    run_with_plant(sc, body)
