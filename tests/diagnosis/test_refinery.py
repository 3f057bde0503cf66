"""Real refinery loops labelled by the plant's engineers (../shared/data/refinery-stiction-dev):
the chain must keep finding the sticky valves and leave the others alone (issue 24).

The figure is the one ``../shared/tools/score_real.py stiction`` computes with the CLI: a
record counts as "stiction found" when the cause is ``stiction`` or ``stiction.detected`` is
true; accuracy per tag, then averaged over the stiction and the non-stiction tags. Measured
0.978 (no false-alarm tag); the floor is issue 46's transfer figure, 0.85 with no false-alarm
tag.
"""

from __future__ import annotations

import csv
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import pytest

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.chain import ChainParams
from plantcheck.diagnosis.stick_slip import StickSlipParams
from plantcheck.service.records import read_record

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "refinery-stiction-dev"

pytestmark = pytest.mark.skipif(
    not (DATA / "labels.csv").is_file(),
    reason=f"refinery records not found at {DATA} (../shared is not beside the repository)",
)


def loop_type_of(tag: str) -> str:
    """The loop type from the ISA tag, as the scorer reads it."""
    t = tag.upper()
    for key, lt in (("FIC", "flow"), ("LIC", "level"), ("PDIC", "pressure"), ("PIC", "pressure")):
        if key in t:
            return lt
    return "other"


def test_refinery_tag_balanced_accuracy() -> None:
    by_tag: dict[tuple[str, bool], list[bool]] = defaultdict(list)
    for r in csv.DictReader((DATA / "labels.csv").open()):
        rec = read_record(DATA / r["file"])
        d = diagnose(
            rec.signals["pv"],
            rec.signals["op"],
            rec.sample_time_s,
            sp=rec.signals.get("sp"),
            auto=rec.auto,
            loop_type=loop_type_of(r["tag"]),
            quantify=False,
        )
        found = d.cause == "stiction" or d.stiction.detected
        sticky = r["stiction"] == "1"
        by_tag[(r["tag"], sticky)].append(found == sticky)
    pos = [sum(v) / len(v) for (_, lab), v in by_tag.items() if lab]
    neg = [sum(v) / len(v) for (_, lab), v in by_tag.items() if not lab]
    accuracy = 0.5 * (sum(pos) / len(pos) + sum(neg) / len(neg))
    false_alarm_tags = sum(x < 1.0 for x in neg)
    assert accuracy >= 0.85, f"tag-balanced accuracy {accuracy:.3f}"
    assert false_alarm_tags == 0, f"{false_alarm_tags} tags with false alarms"


# Sticky flow windows of 2411FIC20102 after a set-point step: OP ramps by 1-2 % while the flow
# stays put for minutes, then the flow jumps. Read as "any process" that could be a lag of 16-32
# samples behind a dead time of 8; a flow follows its valve within seconds.
FLOW_AFTER_STEP = (
    "records/stic_2411FIC20102_1003_0004.csv",
    "records/stic_2411FIC20102_1008_1552.csv",
    "records/stic_2411FIC20102_1117_1652.csv",
)


@pytest.mark.parametrize("name", FLOW_AFTER_STEP)
def test_a_flow_follows_its_valve_within_seconds(name: str) -> None:
    rec = read_record(DATA / name)
    g = rec.signals

    def cause(loop_type: str) -> str:
        d = diagnose(g["pv"], g["op"], rec.sample_time_s, sp=g["sp"], loop_type=loop_type)
        return d.cause

    assert cause("flow") == "stiction"
    assert cause("pressure") != "stiction"  # the same trend, with no bound on the dynamics


def test_a_ramp_that_is_much_of_ops_travel_is_confirmed_in_noise() -> None:
    """A sticky flow window whose one slip ends a ramp of a third of OP's travel in the window:
    the valve-step model fits to the noise and explains the flow 2.2 x better than OP, short
    of the 2.5 x any such candidate needs (``StickSlipParams.evidence_ratio_ramp_fitted``)."""
    rec = read_record(DATA / "records/stic_2411FIC20102_1107_0006.csv")
    g = rec.signals

    def cause(**stick_slip: float) -> str:
        params = ChainParams(stick_slip=replace(StickSlipParams(), **stick_slip))
        d = diagnose(
            g["pv"], g["op"], rec.sample_time_s, sp=g["sp"], loop_type="flow", params=params
        )
        return d.cause

    assert cause(evidence_ratio_ramp_fitted=2.5) != "stiction"
    assert cause() == "stiction"
