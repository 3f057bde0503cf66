"""Register decoding cases, Telegraf style: each tests/modbus_cases/*.json holds a tag, its
registers as read, the source's byte/word order and scaling, and the expected value or status."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from plantcheck.connectors.modbus import ModbusTag, decode_block, plan_blocks
from plantcheck.core import status_codes

CASES = sorted((Path(__file__).parents[1] / "modbus_cases").glob("*.json"))


@pytest.mark.parametrize("case", CASES, ids=[c.stem for c in CASES])
def test_decoding_case(case: Path) -> None:
    spec = json.loads(case.read_text())
    tag = ModbusTag.parse(7, spec["tag"], spec.get("gain", 1.0), spec.get("offset", 0.0))
    (block,) = plan_blocks([tag])
    (sample,) = decode_block(
        block, spec["registers"], 1, 2, spec.get("word_order", "big"), spec.get("byte_order", "big")
    )
    assert sample.tag_id == 7 and sample.ts_us == 1 and sample.recv_us == 2
    if "expected" in spec:
        assert sample.status == status_codes.GOOD
        assert sample.value == pytest.approx(spec["expected"])
    else:
        assert sample.status == getattr(status_codes, spec["expected_status"])
        assert sample.value is None


def test_blocks_are_contiguous_and_at_most_125_registers() -> None:
    tags = [ModbusTag.parse(i, f"hr:{10 * i}:float32") for i in range(40)]
    tags.append(ModbusTag.parse(99, "ir:3:int16"))
    blocks = plan_blocks(tags)
    assert all(b.count <= 125 for b in blocks)
    assert sum(len(b.tags) for b in blocks) == 41
    assert {b.table for b in blocks} == {"hr", "ir"}
