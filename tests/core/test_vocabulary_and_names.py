"""The shared vocabulary (``core/vocabulary.py``) is the contract's, and the one id rule
(``core/names.py``) takes DCS tag names and refuses what a URL path or a table cannot hold."""

from __future__ import annotations

import pytest

from plantcheck.core.names import check_loop_id
from plantcheck.core.vocabulary import CAUSES, LOOP_TYPES, STATES, Cause, LoopType
from plantcheck.diagnosis.result import action_for, state_of


def test_the_contracts_words() -> None:
    assert LOOP_TYPES == ("flow", "pressure", "level", "temperature", "composition", "other")
    assert STATES == ("ok", "warning", "fault", "unknown")
    assert len(CAUSES) == 16 and CAUSES[0] == "ok"
    assert LoopType.level == "level" and f"{Cause.stiction}" == "stiction"


@pytest.mark.parametrize("cause", CAUSES)
def test_every_cause_has_a_state_and_an_action(cause: str) -> None:
    assert state_of(cause) in STATES
    assert action_for(cause)["code"] != "investigate"


@pytest.mark.parametrize("name", ["FIC101", "10-PIC-301", "u1.LIC_2", "A" * 64])
def test_tag_names_are_loop_ids(name: str) -> None:
    assert check_loop_id(name) == name


@pytest.mark.parametrize("name", ["", "A" * 65, "FIC 101", "FIC/101", "FIC101?", "é"])
def test_what_a_path_cannot_hold_is_refused_with_the_rule(name: str) -> None:
    with pytest.raises(ValueError, match="letters, digits"):
        check_loop_id(name)
