"""``plantcheck model fit``: rebuild the shipped learned decision from the simulated corpus
(issue 46). The fitting library (the ``fit`` extra: LightGBM) is imported by this command
only."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Annotated

import typer

from plantcheck.service.cli_common import fail, writable_folder

model_app = typer.Typer(
    help="The learned cause decision: rebuild it from the simulated corpus.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@model_app.command("fit", short_help="Fit the cause model on the simulated corpus and save it.")
def fit_cmd(
    windows: Annotated[
        int,
        typer.Option(
            min=60,
            help="Corpus windows to fit on (calibration and check: a quarter as many each, "
            "at most 8,000).",
        ),
    ] = 64_000,  # service.cause_model_fit.FIT_WINDOWS (a test holds them equal)
    out: Annotated[
        Path | None,
        typer.Option(
            help="Model file to write (default: the one the package reads).", show_default=False
        ),
    ] = None,
    jobs: Annotated[
        int | None, typer.Option(min=1, help="Processes (default: every core).")
    ] = None,
    cache: Annotated[
        Path | None,
        typer.Option(help="Folder keeping the corpus' evidence and shapes between runs."),
    ] = None,
    tree_seed: Annotated[
        int,
        typer.Option(
            min=0,
            help="LightGBM's seed for its row and column subsampling (the shipped fits use 0; "
            "other seeds show how far one fit's readings are a draw).",
        ),
    ] = 0,
    shape_seed: Annotated[
        int,
        typer.Option(
            min=0,
            help="PyTorch's seed for the shape network's first weights and its batches (the "
            "shipped fits use 0; other seeds show how far the blend's readings are a draw).",
        ),
    ] = 0,
    shape: Annotated[
        bool,
        typer.Option(
            help="Fit the shape network (PyTorch) and blend it with the trees; --no-shape: "
            "the trees alone."
        ),
    ] = True,
    networks: Annotated[
        int,
        typer.Option(
            min=1,
            help="Shape networks fitted from seeds shape-seed, shape-seed + 1... and averaged "
            "(the shipped fits use 2).",
        ),
    ] = 2,  # service.cause_model_fit.SHAPE_NETWORKS (a test holds them equal)
    as_json: Annotated[bool, typer.Option("--json", help="Print the figures as JSON.")] = False,
) -> None:
    """Draw the corpus (simulator.corpus), fit the trees, calibrate, check, write OUT.

    Progress goes to stderr; the check figures (macro-F1, per-class F1, calibration error,
    the rules' macro-F1 on the same windows) to stdout. About two and a half hours on 2 cores
    for the default 64,000 windows: the evidence and the shapes of the 272,000 windows the
    fit reads (the trees and networks read four times as many, each fault's twin simulated
    beside it) drawn in one pass, each window simulated once (about 95 minutes at 48 a
    second), then the fit (about 55 minutes with two networks); about 5 GB of memory at the
    peak. With ``--cache`` a second run only fits, and one with more windows draws only the
    new ones.
    """
    # imported here: the diagnosis package costs the other commands' start-up its numpy
    from plantcheck.diagnosis.cause_model import SHIPPED_MODEL

    out = out or SHIPPED_MODEL
    # before the corpus' draw (up to half an hour), and before torch and the simulator are
    # imported (seconds): a path found unwritable after them wastes them
    if out.is_dir():
        raise fail(f"--out {out}: is a folder; give the model file's path (e.g. {out}/model.npz)")
    writable_folder(out.parent, f"--out {out}")
    if cache is not None:
        writable_folder(cache, f"--cache {cache}")
    try:
        import lightgbm  # noqa: F401

        if shape:
            import torch  # noqa: F401
    except ImportError as exc:
        raise fail(f"model fit needs {exc.name}: pip install -e '.[fit]'") from None
    from plantcheck.service.cause_model_fit import fit_model, save_model

    t0 = time.monotonic()
    rep = fit_model(
        windows,
        jobs,
        lambda m: print(m, file=sys.stderr, flush=True),
        cache,
        tree_seed=tree_seed,
        shape=shape,
        shape_seed=shape_seed,
        networks=networks,
    )
    save_model(rep.model, out)
    figures = {
        "model": str(out),
        "windows": rep.windows,
        "temperature": round(rep.temperature, 3),
        "check_macro_f1": round(rep.macro_f1, 3),
        "check_trees_macro_f1": round(rep.trees_macro_f1, 3),
        "shape_weight": rep.model.shape_weight,
        "check_class_f1": {k: round(v, 3) for k, v in rep.class_f1.items()},
        "check_ece": round(rep.ece, 3),
        "rules_macro_f1": round(rep.rules_macro_f1, 3),
        "seconds": round(time.monotonic() - t0, 1),
    }
    if as_json:
        typer.echo(json.dumps(figures))
        return
    typer.echo(
        f"wrote {out}: check macro-F1 {figures['check_macro_f1']} (trees alone "
        f"{figures['check_trees_macro_f1']}, shape network's weight "
        f"{figures['shape_weight']}; rules "
        f"{figures['rules_macro_f1']}), calibration error {figures['check_ece']}, "
        f"temperature {figures['temperature']}, {figures['seconds']} s"
    )
    for cause, f1 in figures["check_class_f1"].items():  # type: ignore[attr-defined]
        typer.echo(f"  {cause:22s} F1 {f1}")
