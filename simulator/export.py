"""Files the simulator writes: loop records (contracts §1), their truth, the register map.

- ``write_records``: run the plant as fast as it goes for a duration and write one CSV per
  loop (``timestamp,sp,pv,op[,mv],mode``) plus ``<id>.json`` with the true cause and S, J.
- ``register_map``: the Modbus address of every signal; ``map_csv`` / ``map_toml`` render it
  for spreadsheets and for the service configuration (contracts §4 ``[[loop]]`` tables).
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from plantcheck.simulator.plant import Plant
from plantcheck.simulator.scenario import (
    HEADER_REGISTERS,
    REGISTERS_PER_LOOP,
    SIGNALS,
    LoopSpec,
    Scenario,
)


@dataclass(frozen=True)
class RegisterEntry:
    """One served signal: loop, signal name, first register (0-based), unit."""

    loop: str
    signal: str
    address: int
    unit: str


def loop_base(index: int) -> int:
    """First register of the ``index``-th loop (0-based): 10 + 10·index."""
    return HEADER_REGISTERS + REGISTERS_PER_LOOP * index


def register_map(scenario: Scenario) -> list[RegisterEntry]:
    """Every loop signal's float32 address (same in holding and input registers)."""
    out = []
    for i, spec in enumerate(scenario.loop):
        for j, sig in enumerate(SIGNALS):
            unit = spec.unit if sig in ("SP", "PV") else ("%" if sig in ("OP", "MV") else "")
            out.append(RegisterEntry(spec.id, sig, loop_base(i) + 2 * j, unit))
    return out


def map_csv(scenario: Scenario) -> str:
    """The register map as CSV: loop,signal,address,type,word_order,byte_order,unit."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["loop", "signal", "address", "type", "word_order", "byte_order", "unit"])
    w.writerow(["_clock", "time", 0, "float64", scenario.modbus.word_order, "", "s"])
    w.writerow(["_clock", "steps", 4, "uint32", scenario.modbus.word_order, "", ""])
    for e in register_map(scenario):
        bo = scenario.modbus.byte_order
        w.writerow([e.loop, e.signal, e.address, "float32", scenario.modbus.word_order, bo, e.unit])
    return buf.getvalue()


def map_toml(
    scenario: Scenario,
    protocol: str = "modbus",
    source: str | None = None,
    poll_interval_s: float | None = None,
    timeout_s: float | None = None,
) -> str:
    """``[[source]]`` and ``[[loop]]`` tables of the service configuration for this plant,
    reading it over Modbus TCP (register addresses) or OPC UA (node ids), with the source's
    ``poll_interval_s`` and ``timeout_s`` (s) when given."""
    name = source or f"sim-{protocol}"
    if protocol == "opcua":
        lines = ["[[source]]", f'name = "{name}"', 'protocol = "opcua"']
        lines += [f'url = "{scenario.opcua.url}"', ""]
    else:
        m = scenario.modbus
        lines = [
            "[[source]]",
            f'name = "{name}"',
            'protocol = "modbus"',
            f'host = "{m.host}"',
            f"port = {m.port}",
            f"device_id = {m.device_id}",
            f'word_order = "{m.word_order}"',
            f'byte_order = "{m.byte_order}"',
            # the plant's time (registers 0-3) stamps the values: right at any speed
            'clock = "hr:0:float64"',
            "",
        ]
    if poll_interval_s is not None:
        lines.insert(-1, f"poll_interval_s = {poll_interval_s:g}")
    if timeout_s is not None:
        lines.insert(-1, f"timeout_s = {timeout_s:g}")
    specs = {spec.id: spec for spec in scenario.loop}
    for e in register_map(scenario):
        spec = specs[e.loop]
        if e.signal == SIGNALS[0]:
            lines += [
                "[[loop]]",
                f'id = "{spec.id}"',
                f'type = "{spec.type}"',
                f'source = "{name}"',
                # the PV's span: a retuning proposal's gain in % of OP per % of span
                f"controller = {{ pv_span = {spec.range[1] - spec.range[0]:g} }}",
            ]
        if e.signal != "MV" or spec.expose_mv:
            address = (
                f"ns=2;s={spec.id}.{e.signal}" if protocol == "opcua" else f"hr:{e.address}:float32"
            )
            lines.append(f'{e.signal.lower()} = "{address}"')
        if e.signal == SIGNALS[-1]:
            lines.append("")
    return "\n".join(lines)


def truth(spec: LoopSpec) -> dict[str, object]:
    """The labelled truth of a loop: its cause and, for sticky valves, S and J (% travel)."""
    sticky = spec.valve.model != "linear" and spec.valve.S > 0
    return {
        "loop": spec.id,
        "loop_type": spec.type,
        "cause": spec.cause,
        "valve_model": spec.valve.model,
        "S": spec.valve.S if sticky else None,
        "J": spec.valve.J if sticky else None,
        "positioner_fault": spec.positioner.fault if spec.positioner else None,
        "unit": spec.unit,
        "range": list(spec.range),
    }


def _fmt(x: float) -> str:
    return "" if math.isnan(x) else f"{x:.6g}"


def write_records(
    scenario: Scenario,
    out_dir: Path,
    duration_s: float,
    start: datetime,
    progress: Callable[[float], None] | None = None,
) -> list[Path]:
    """Simulate ``duration_s`` seconds at full speed; write ``<id>.csv`` and ``<id>.json``.

    ``progress`` is called with the fraction done about every 5 %. Returns the CSV paths.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    plant = Plant(scenario, start)
    n = max(1, math.ceil(duration_s / plant.ts))
    files = [(out_dir / f"{s.id}.csv").open("w", encoding="utf-8") for s in scenario.loop]
    try:
        for f, spec in zip(files, scenario.loop, strict=True):
            f.write("timestamp,sp,pv,op" + (",mv" if spec.expose_mv else "") + ",mode\n")
        every = max(1, n // 20)
        for k in range(n):
            plant.step()
            stamp = plant.time.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
            for i, (f, spec) in enumerate(zip(files, scenario.loop, strict=True)):
                sp, pv, op, mv, mode = plant.values[i]
                row = [stamp, _fmt(sp), _fmt(pv), _fmt(op)]
                if spec.expose_mv:
                    row.append(_fmt(mv))
                row.append(str(int(mode)))
                f.write(",".join(row) + "\n")
            if progress and (k + 1) % every == 0:
                progress((k + 1) / n)
    finally:
        for f in files:
            f.close()
    for spec in scenario.loop:
        (out_dir / f"{spec.id}.json").write_text(json.dumps(truth(spec), indent=2) + "\n")
    return [out_dir / f"{s.id}.csv" for s in scenario.loop]
