"""Control-loop diagnosis: pure numpy/scipy functions, no I/O (methods.md).

The public entry points are :func:`diagnose_loop` (the standard or the advanced chain, by the
stem position's coverage), :func:`diagnose` (the PCU standard chain) and
:func:`detect_oscillation` (oscillation test on any one signal).
"""

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
