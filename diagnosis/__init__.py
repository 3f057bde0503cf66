"""Control-loop diagnosis: pure numpy/scipy functions, no I/O (methods.md).

The public entry points are :func:`diagnose_loop` (the standard or the advanced chain, by the
stem position's coverage), :func:`diagnose` (the PCU standard chain) and
:func:`detect_oscillation` (oscillation test on any one signal).

They are loaded when first asked for (PEP 562): importing one submodule (``signal_tools`` for
the record reader's median, ``result`` for the causes) runs this file, which would otherwise
load the whole chain and its model code (0.15-0.2 s) into commands that diagnose nothing.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from plantcheck.diagnosis.baseline import Baseline, baseline_from
    from plantcheck.diagnosis.chain import ChainParams, diagnose, diagnose_advanced
    from plantcheck.diagnosis.chain_choice import diagnose_loop
    from plantcheck.diagnosis.oscillation import (
        OscillationParams,
        OscillationResult,
        detect_oscillation,
    )
    from plantcheck.diagnosis.result import CAUSES, Diagnosis
    from plantcheck.diagnosis.stiction_vote import LOOP_TYPES

_HOME = {
    "CAUSES": "result",
    "LOOP_TYPES": "stiction_vote",
    "Baseline": "baseline",
    "ChainParams": "chain",
    "Diagnosis": "result",
    "OscillationParams": "oscillation",
    "OscillationResult": "oscillation",
    "baseline_from": "baseline",
    "detect_oscillation": "oscillation",
    "diagnose": "chain",
    "diagnose_advanced": "chain",
    "diagnose_loop": "chain_choice",
}
"""Each public name's submodule."""

__all__ = [
    "CAUSES",
    "LOOP_TYPES",
    "Baseline",
    "ChainParams",
    "Diagnosis",
    "OscillationParams",
    "OscillationResult",
    "baseline_from",
    "detect_oscillation",
    "diagnose",
    "diagnose_advanced",
    "diagnose_loop",
]


def __getattr__(name: str) -> Any:
    if name not in _HOME:
        raise AttributeError(f"module 'plantcheck.diagnosis' has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{_HOME[name]}"), name)
