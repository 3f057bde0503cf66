"""``plantcheck simulate``: the bundled plant simulator (servers, or records to CSV)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from plantcheck.service.cli_common import (
    fail,
    parse_duration,
    parse_host_port,
    writable_folder,
)
from plantcheck.service.logs import configure_for_command

if TYPE_CHECKING:
    from plantcheck.simulator.scenario import Scenario


def _apply_overrides(
    sc: Scenario, modbus: str | None, opcua: str | None, admin: str | None, speed: float | None
) -> Scenario:
    upd: dict[str, object] = {}
    try:
        if modbus is not None:
            if modbus == "off":
                upd["modbus"] = sc.modbus.model_copy(update={"enabled": False})
            else:
                host, port = parse_host_port(modbus)
                upd["modbus"] = sc.modbus.model_copy(update={"host": host, "port": port})
        if admin is not None:
            if admin == "off":
                upd["admin"] = sc.admin.model_copy(update={"enabled": False})
            else:
                host, port = parse_host_port(admin)
                upd["admin"] = sc.admin.model_copy(update={"host": host, "port": port})
    except ValueError as exc:
        raise fail(f"--modbus/--admin: {exc}") from None
    if opcua is not None:
        if opcua == "off":
            upd["opcua"] = sc.opcua.model_copy(update={"enabled": False})
        elif not opcua.startswith("opc.tcp://"):
            raise fail(f"--opcua: {opcua!r} is not an opc.tcp:// URL (or 'off')")
        else:
            upd["opcua"] = sc.opcua.model_copy(update={"url": opcua})
    if speed is not None:
        if not 0 < speed <= 100_000:
            raise fail("--speed must be > 0 and <= 100000 (simulated seconds per second)")
        upd["clock"] = sc.clock.model_copy(update={"speed": speed})
    return sc.model_copy(update=upd)


def _poll_interval_s(sc: Scenario, protocol: str) -> float:
    """The exported source's poll interval (wall s) at the scenario's speed. A Modbus poll at
    the device's own update rate beats against it and misses samples (a fifth of them at 20x,
    each filled by interpolation, which blunts the stick-slip jumps the stiction tests read):
    polled twice per simulated sample (Nyquist), a repeated clock reading stores nothing. An
    OPC UA subscription samples on the server, once per simulated sample."""
    one_sample = sc.clock.sample_time_s / sc.clock.speed
    return one_sample / 2 if protocol == "modbus" else one_sample


def simulate_cmd(
    config: Annotated[
        Path | None,
        typer.Option("--config", help="Scenario TOML (default: the bundled 11-loop plant)."),
    ] = None,
    modbus: Annotated[
        str | None, typer.Option(help="Modbus TCP HOST:PORT, or 'off' (default 127.0.0.1:5020).")
    ] = None,
    opcua: Annotated[
        str | None,
        typer.Option(help="OPC UA endpoint URL, or 'off' (default opc.tcp://127.0.0.1:4840/...)."),
    ] = None,
    admin: Annotated[
        str | None, typer.Option(help="Admin interface HOST:PORT, or 'off' (default :5021).")
    ] = None,
    speed: Annotated[
        float | None,
        typer.Option(
            help="Simulated seconds per wall second (1 = real time, 100 = 100x); default: the "
            "scenario's clock.speed (1 in the bundled scenario); with --export-map, the map "
            "polls at this pace."
        ),
    ] = None,
    to_csv: Annotated[
        Path | None,
        typer.Option(
            "--to-csv", help="Write each loop's record (docs/contracts.md §1) here and exit."
        ),
    ] = None,
    duration: Annotated[
        str, typer.Option(help="With --to-csv: simulated duration, e.g. 7200, 90m, 2h, 1d.")
    ] = "2h",
    export_map: Annotated[
        Path | None,
        typer.Option(help="Write the register map to this .csv or .toml file and exit."),
    ] = None,
    map_protocol: Annotated[
        str,
        typer.Option(help="With --export-map .toml: the source protocol, modbus or opcua."),
    ] = "modbus",
    quiet: Annotated[bool, typer.Option(help="Do not print the register map at start.")] = False,
) -> None:
    """Run the simulated plant: Modbus TCP and OPC UA servers on loopback, faults on demand.

    With --to-csv, simulate --duration at full speed and write one CSV record per loop plus a
    JSON file with its true cause and S, J instead of serving.
    """
    # the output paths and the duration first, before the simulator's modules are imported
    # and the scenario read: a mistyped path is named at once
    if export_map is not None:
        if export_map.suffix not in (".csv", ".toml"):
            raise fail("--export-map: the file name must end in .csv or .toml")
        if map_protocol not in ("modbus", "opcua"):
            raise fail(f"--map-protocol must be modbus or opcua, not {map_protocol!r}")
        writable_folder(export_map.parent, f"--export-map {export_map}")
    elif to_csv is not None:
        try:
            seconds = parse_duration(duration)
        except ValueError as exc:
            raise fail(f"--duration: {exc}") from None
        writable_folder(to_csv, f"--to-csv {to_csv}")

    from plantcheck.core.toml_config import ConfigError
    from plantcheck.simulator.export import map_csv, map_toml, write_records
    from plantcheck.simulator.scenario import load_scenario

    try:
        scenario = load_scenario(config)
    except ConfigError as exc:
        raise fail(f"invalid scenario: {exc}") from None
    scenario = _apply_overrides(scenario, modbus, opcua, admin, speed)
    if export_map is not None:
        text = (
            map_csv(scenario)
            if export_map.suffix == ".csv"
            else map_toml(
                scenario,
                protocol=map_protocol,
                poll_interval_s=(
                    _poll_interval_s(scenario, map_protocol) if speed is not None else None
                ),
            )
        )
        export_map.write_text(text, encoding="utf-8")
        typer.echo(f"register map of {len(scenario.loop)} loops written to {export_map}")
        return
    if to_csv is not None:
        start = scenario.clock.start or datetime.now(UTC).replace(microsecond=0)

        def progress(frac: float) -> None:
            typer.echo(f"simulated {100 * frac:.0f} %", err=True)

        files = write_records(scenario, to_csv, seconds, start, progress)
        typer.echo(f"wrote {len(files)} loop records of {seconds:g} s to {to_csv}")
        return
    if not quiet:
        typer.echo(map_csv(scenario), nl=False)
    _serve(scenario)


def _serve(scenario: Scenario) -> None:
    import asyncio  # here, not at the top: `diagnose` of one record needs no event loop

    from plantcheck.simulator.runner import PlantRunner

    configure_for_command("info")

    async def main() -> None:
        runner = PlantRunner(scenario)
        task = asyncio.create_task(runner.run())
        ready = asyncio.create_task(runner.ready.wait())
        # a server that cannot start (its port taken) ends the run before it is ready: its
        # error is the command's, not a simulator that runs on without that server
        await asyncio.wait((task, ready), return_when=asyncio.FIRST_COMPLETED)
        if not ready.done():
            ready.cancel()
            await task
            return
        m, o, a = scenario.modbus, scenario.opcua, scenario.admin
        parts = [f"{len(scenario.loop)} loops at {scenario.clock.speed:g}x real time"]
        if m.enabled:
            parts.append(f"Modbus TCP {m.host}:{m.port} (device {m.device_id})")
        if o.enabled:
            parts.append(f"OPC UA {o.url}")
        if a.enabled:
            parts.append(f"admin {a.host}:{a.port}")
        typer.echo("plantcheck simulator: " + "; ".join(parts), err=True)
        if m.enabled and scenario.clock.speed != 1:
            # Modbus carries no time: a client stamps values when it polls them, which at any
            # speed but 1 is not the plant's time, and the diagnosis reads wrong periods
            typer.echo(
                f"plantcheck simulator: WARNING: at {scenario.clock.speed:g}x, Modbus clients "
                "must stamp values with the plant time in registers 0-3: set clock = "
                '"hr:0:float64" on the [[source]] (`--export-map` writes it), or read the '
                "plant over OPC UA (simulator README, Clock)",
                err=True,
            )
        await task

    try:
        asyncio.run(main())
    except OSError as exc:
        raise fail(
            f"cannot serve ({exc}); choose free ports with --modbus/--opcua/--admin"
        ) from None
