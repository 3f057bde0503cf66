"""Diagnose one stored loop window: the function the scheduler's worker pool runs.

Takes plain numpy arrays (picklable, no database handle) and returns the contracts §2 object,
so it runs in a worker process while the event loop keeps ingesting and serving.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis import Baseline, diagnose_loop
from plantcheck.diagnosis.chain import default_chain_params
from plantcheck.diagnosis.controller_forms import ControllerForm
from plantcheck.diagnosis.retuning import RetuneParams
from plantcheck.diagnosis.tuning_proposal import TuningSettings

FloatArray = NDArray[np.float64]


def warm_worker() -> None:
    """Run once in each worker at start: unpickling it imports this module, so the chain, and
    the first diagnosis does not pay for imports. It lives here, not with the scheduler: a
    worker then imports the chain alone (0.3 s on a slow machine), not the scheduler's store,
    web and job stack (1.8-2 s and their memory in every worker)."""


def automatic(mode: FloatArray | None) -> NDArray[np.bool_] | None:
    """Automatic-mode mask from a stored mode signal (contracts §1: 1 = automatic).

    Unknown mode (NaN, no mode tag) counts as automatic: the window checks then judge the data.
    """
    if mode is None or not np.isfinite(mode).any():
        return None
    return np.asarray(~np.isfinite(mode) | (np.rint(mode) == 1.0))


def diagnose_window(
    values: dict[str, FloatArray],
    sample_time_s: float,
    loop_type: str,
    notes: list[str] | None = None,
    quantify: bool = True,
    baseline: tuple[float, str] | None = None,
    controller: dict[str, Any] | None = None,
    dead_time_s: float | None = None,
) -> dict[str, Any]:
    """The diagnosis (contracts §2 JSON object) of one aligned window.

    ``values`` holds ``pv``, ``op`` and optionally ``sp``, ``mv``, ``mode`` on one grid of
    ``sample_time_s`` seconds (missing samples NaN). The chain is chosen by ``diagnose_loop``
    (the advanced one when MV was stored for at least half the window).
    ``quantify`` off skips the Hammerstein S/J estimate (methods §6.1), the costly part.
    ``baseline`` is the loop's healthy error σ (PV units) and its source, when known;
    ``controller`` the loop's controller form (``ControllerForm`` fields) for the retuning,
    ``dead_time_s`` its configured dead time for the Harris index.
    """
    pv, op = values["pv"], values["op"]
    sp = values.get("sp")
    if sp is not None and not np.isfinite(sp).any():
        sp = None
    auto = automatic(values.get("mode"))
    d = diagnose_loop(
        pv,
        op,
        sample_time_s,
        sp=sp,
        mv=values.get("mv"),
        auto=auto,
        loop_type=loop_type,
        quantify=quantify,
        params=replace(
            default_chain_params(),
            retuning=_retuning(controller or {}),
            dead_time_s=dead_time_s,
        )
        if controller or dead_time_s is not None
        else None,
        baseline=Baseline(baseline[0], source=baseline[1]) if baseline is not None else None,
    )
    return d.with_notes_first(notes or []).to_dict()


def _retuning(controller: dict[str, Any]) -> TuningSettings:
    """The retuning's settings from the loop's ``controller`` configuration: its form, and
    for a level loop whether the proposal is for averaging or tight control."""
    form = {k: v for k, v in controller.items() if k != "level_control"}
    level = {"level_control": controller["level_control"]} if "level_control" in controller else {}
    return TuningSettings(form=ControllerForm(**form), retune=RetuneParams(**level))
