"""The ``plantcheck`` command line (contracts.md §2–§3).

Exit status: 0 when a diagnosis was made (whatever its cause), 2 when the input cannot be
used at all (one line on stderr naming the problem and the fix), 1 on an internal error
(one line, never a traceback).
"""

from __future__ import annotations

import json
import sys
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from plantcheck.core.vocabulary import LoopType
from plantcheck.service.allocator import tune_allocator
from plantcheck.service.blas_threads import one_blas_thread
from plantcheck.service.cli_common import fail
from plantcheck.service.cli_model import model_app
from plantcheck.service.cli_run import demo_cmd, run_cmd, worker_cmd
from plantcheck.service.cli_simulate import simulate_cmd
from plantcheck.service.cli_store import db_app, import_cmd, ingest_cmd
from plantcheck.service.logs import LogOptions

if TYPE_CHECKING:
    from plantcheck.diagnosis import Diagnosis
    from plantcheck.service.records import LoopRecordFile

# The diagnosis library (numpy, scipy.signal: about 0.8 s) is imported by the commands that
# diagnose, so that `plantcheck --version`, `--help` and the service commands start at once.

DEFAULT_MAX_SAMPLES = 200_000

app = typer.Typer(
    name="plantcheck",
    help="Monitor and diagnose industrial control loops (stiction, tuning, disturbances).",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    # plain help text: rendering it with rich costs 0.1 s of imports per call (issue 29)
    rich_markup_mode=None,
)


class LogLevel(StrEnum):
    """``--log-level`` values."""

    debug = "debug"
    info = "info"
    warning = "warning"
    error = "error"


class Decision(StrEnum):
    """``diagnose --decision`` values (issue 46)."""

    rules = "rules"
    learned = "learned"


class LevelControl(StrEnum):
    """``diagnose --level-control`` values (issue 48): what a level loop's retuning aims at."""

    averaging = "averaging"
    tight = "tight"


class LogFormat(StrEnum):
    """``--log-format`` values."""

    plain = "plain"
    json = "json"


def _version(value: bool) -> None:
    if value:
        from plantcheck import __version__

        typer.echo(f"plantcheck {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(
    ctx: typer.Context,
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Show the version."),
    ] = False,
    log_level: Annotated[
        LogLevel | None,
        typer.Option(
            "--log-level", help="debug, info, warning or error (default: info for the service)."
        ),
    ] = None,
    log_format: Annotated[
        LogFormat, typer.Option("--log-format", help="plain lines or one JSON object per line.")
    ] = LogFormat.plain,
) -> None:
    """plantcheck: on-line monitoring and diagnosis of control loops."""
    ctx.obj = LogOptions(log_level.value if log_level else None, log_format.value)


ROWS_PER_SAMPLE = 2
"""Rows read per sample diagnosed (``--max-samples``): room for duplicate or irregular rows."""


def _load(
    file: Path, sample_time: float | None, need: tuple[str, ...], max_samples: int
) -> LoopRecordFile:
    """The record's last rows, memory bounded by ``max_samples`` whatever the file's size."""
    from plantcheck.service.records import RecordError, read_record, require

    try:
        rec = read_record(file, sample_time, max_rows=ROWS_PER_SAMPLE * max_samples)
        require(rec, file, need)
    except RecordError as exc:
        raise fail(str(exc)) from None
    return rec


def _tail(rec: LoopRecordFile, max_samples: int) -> tuple[slice, list[str]]:
    n = rec.t.size
    if n <= max_samples:
        return slice(0, n), []
    note = (
        f"record has {n} samples: diagnosed the last {max_samples} "
        "(use --max-samples to change; a diagnosis window is normally hours to a day)"
    )
    typer.echo(f"plantcheck: {note}", err=True)
    return slice(n - max_samples, n), [note]


def _summary(d: Diagnosis) -> str:
    lines = [
        f"cause:       {d.cause}  (confidence {d.confidence:.2f})",
        f"chain:       {d.chain}, loop type {d.loop_type}, {d.samples} samples at "
        f"{d.sample_time_s:g} s",
    ]
    if d.oscillation:
        o = d.oscillation
        lines.append(
            f"oscillation: period {o.period_s or 0:.1f} s, amplitude {o.amplitude or 0:.3g}, "
            f"regularity {o.regularity or 0:.2f}"
        )
    else:
        lines.append("oscillation: none")
    st = d.stiction
    if st.tests:
        shown = ", ".join(
            f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}" for k, v in st.tests.items()
        )
        lines.append(f"stiction:    {'detected' if st.detected else 'not detected'} ({shown})")
    for ev in st.events or ():
        lines.append(
            f"event:       stuck from {ev.start:.0f} s, slipped by {ev.end:.0f} s: "
            f"OP travel {ev.op_travel:.2f} %, PV jump {ev.pv_jump:+.3g}"
        )
    est = st.estimate
    if est is not None and est.S is not None:
        j = f", J = {est.J:.2f} %" if est.J is not None else ""
        sure = "reliable" if est.reliable else "not reliable"
        lines.append(f"size:        S = {est.S:.2f} %{j} ({est.method}, {sure})")
    if d.valve is not None:
        lines.append(f"valve:       {d.valve.state} (advanced chain, from MV)")
    for a in d.actions:
        lines.append(f"action:      {a.text}")
    for note in d.notes:
        lines.append(f"note:        {note}")
    return "\n".join(lines)


@app.command("diagnose", short_help="Diagnose one recorded loop: what is wrong and what to do.")
def diagnose_cmd(
    file: Annotated[
        Path, typer.Argument(help="Loop record CSV (docs/contracts.md §1).", show_default=False)
    ],
    loop_type: Annotated[
        LoopType, typer.Option("--loop-type", help="Kind of loop; selects the applicable tests.")
    ] = LoopType.other,
    sample_time: Annotated[
        float | None,
        typer.Option("--sample-time", help="Sample time in s (default: median spacing)."),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object (docs/contracts.md §2).")
    ] = False,
    max_samples: Annotated[
        int,
        typer.Option("--max-samples", min=100, help="Diagnose at most the last N samples."),
    ] = DEFAULT_MAX_SAMPLES,
    decision: Annotated[
        Decision,
        typer.Option(
            "--decision",
            help="rules: the chain's rules name the cause, the learned model gives its "
            "probability; learned: the model fitted on simulated plants names it.",
        ),
    ] = Decision.rules,
    baseline: Annotated[
        Path | None,
        typer.Option(
            "--baseline",
            help="A record of the same loop in healthy operation (same format): a window "
            "whose error varies 3 times more is not ok.",
            show_default=False,
        ),
    ] = None,
    dead_time: Annotated[
        float | None,
        typer.Option(
            "--dead-time",
            min=0.0,
            max=86_400.0,
            help="The process dead time in seconds, for the Harris index (kpis); without it "
            "the dead time a set-point step identifies, or none.",
            show_default=False,
        ),
    ] = None,
    level_control: Annotated[
        LevelControl,
        typer.Option(
            "--level-control",
            help="For a level loop's retuning: averaging (a surge volume passes on even "
            "flow; the proposal stays loose on purpose) or tight (the level itself matters).",
        ),
    ] = LevelControl.averaging,
) -> None:
    """Diagnose one recorded loop: what is wrong and what to do."""
    rec = _load(file, sample_time, ("pv", "op"), max_samples)
    base = None if baseline is None else _load(baseline, sample_time, ("pv", "op"), max_samples)
    # after the records are read: a record refused is told without the diagnosis' imports
    from plantcheck.diagnosis import ChainParams, baseline_from, diagnose_loop
    from plantcheck.diagnosis.retuning import RetuneParams
    from plantcheck.diagnosis.tuning_proposal import TuningSettings

    sl, extra = _tail(rec, max_samples)
    pv = rec.signals["pv"][sl]
    op = rec.signals["op"][sl]
    sp = rec.signals["sp"][sl] if "sp" in rec.signals else None
    auto = rec.auto[sl] if rec.auto is not None else None
    mv = rec.signals["mv"][sl] if "mv" in rec.signals else None
    retuning = TuningSettings(retune=RetuneParams(level_control=level_control.value))
    params = ChainParams(decide_by=decision.value, dead_time_s=dead_time, retuning=retuning)
    normal = None
    if baseline is not None and base is not None:
        try:
            normal = baseline_from(base.signals["pv"], base.signals["op"], base.signals.get("sp"),
                                   source=f"from {baseline.name}")  # fmt: skip
        except ValueError as exc:
            raise fail(
                f"{baseline}: {exc}; give --baseline a record of the loop in normal operation"
            ) from None
    d = diagnose_loop(pv, op, rec.sample_time_s, sp=sp, mv=mv, auto=auto,
                      loop_type=loop_type.value, params=params, baseline=normal)  # fmt: skip
    d = d.with_notes_first(rec.notes + extra)
    _emit(d.to_dict() if as_json else _summary(d), as_json)


@app.command("oscillation", short_help="Test one signal of a record for oscillations.")
def oscillation_cmd(
    file: Annotated[
        Path, typer.Argument(help="Record CSV (docs/contracts.md §1).", show_default=False)
    ],
    column: Annotated[str, typer.Option("--column", help="Column to test, e.g. pv or op.")],
    sample_time: Annotated[
        float | None,
        typer.Option("--sample-time", help="Sample time in s (default: median spacing)."),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object (docs/contracts.md §3).")
    ] = False,
    max_samples: Annotated[
        int,
        typer.Option("--max-samples", min=100, help="Test at most the last N samples."),
    ] = DEFAULT_MAX_SAMPLES,
) -> None:
    """Test one signal for a sustained oscillation (Hägglund + Thornhill, then the band-passed
    spectral peaks for irregular and multiple oscillations, then the few-cycle test for slow
    records) and list every oscillation found."""
    import numpy as np

    from plantcheck.diagnosis import detect_oscillation
    from plantcheck.diagnosis.oscillation import SPECTRAL, oscillations_json
    from plantcheck.diagnosis.result import json_safe

    name = column.strip().lower()
    if name not in ("sp", "pv", "op", "mv"):
        raise fail(f"--column must be one of sp, pv, op, mv, not {column!r}")
    rec = _load(file, sample_time, (name,), max_samples)
    sl, _ = _tail(rec, max_samples)
    x = rec.signals[name][sl]
    ok = np.isfinite(x)
    out: dict[str, Any] = {
        "schema": "plantcheck.oscillation/1",
        "column": name,
        "oscillating": False,
        "period_s": None,
        "amplitude": None,
        "regularity": None,
        "samples": int(x.size),
        "sample_time_s": rec.sample_time_s,
    }
    notes = list(rec.notes)
    if ok.sum() < 20 or np.ptp(x[ok]) == 0:
        notes.append("too few numeric samples or a constant signal: no oscillation can be asserted")
    else:
        if not ok.all():
            x = np.interp(np.arange(x.size), np.flatnonzero(ok), x[ok])
            notes.append(f"{int((~ok).sum())} missing samples interpolated")
        res = detect_oscillation(x, rec.sample_time_s, SPECTRAL)
        out.update(
            oscillating=res.oscillating,
            period_s=res.period_s if res.oscillating else None,
            amplitude=res.amplitude if res.oscillating else None,
            regularity=res.regularity,
            oscillations=oscillations_json(res),
        )
        notes.append(res.reason)
    out["notes"] = notes
    if as_json:
        _emit(json_safe(out), True)
    else:
        state = "oscillating" if out["oscillating"] else "not oscillating"
        text = f"{name}: {state}"
        if out["oscillating"]:
            text += f", period {out['period_s']:.1f} s, amplitude {out['amplitude']:.3g}"
        if out["regularity"] is not None:
            text += f", regularity {out['regularity']:.2f}"
        for extra in out.get("oscillations", [])[1:]:
            text += (
                f"\nalso oscillating: period {extra['period_s']:.1f} s, "
                f"amplitude {extra['amplitude']:.3g}"
            )
        _emit(text + "".join(f"\nnote: {n}" for n in notes), False)


app.command(
    "simulate", short_help="Run the simulated plant (Modbus TCP, OPC UA) or write its records."
)(simulate_cmd)
app.command("import", short_help="Backfill a record file into the store (idempotent).")(import_cmd)
app.command("ingest", short_help="Collect the configured sources into the store (no diagnosis).")(
    ingest_cmd
)
app.command("run", short_help="Run the service: ingest, diagnose, serve the API and the page.")(
    run_cmd
)
app.command("worker", short_help='Run queued diagnosis jobs (engine = "queue", PostgreSQL).')(
    worker_cmd
)
app.command("demo", short_help="Run the service against the bundled simulated plant.")(demo_cmd)
app.add_typer(db_app, name="db")
app.add_typer(model_app, name="model", short_help="Rebuild the learned cause decision.")


def _emit(payload: Any, as_json: bool) -> None:
    if as_json:
        typer.echo(json.dumps(payload, ensure_ascii=False))
    else:
        typer.echo(payload)


def main() -> None:
    """Console-script entry point: never shows a traceback."""
    # before any command imports numpy, which reads the thread count once
    one_blas_thread()
    tune_allocator()
    try:
        app()
    except KeyboardInterrupt:
        typer.echo("plantcheck: interrupted", err=True)
        sys.exit(130)
    except SystemExit:
        raise
    except MemoryError:
        typer.echo(
            "plantcheck: error: out of memory; use --max-samples to diagnose fewer samples",
            err=True,
        )
        sys.exit(2)
    except Exception as exc:
        typer.echo(f"plantcheck: internal error: {type(exc).__name__}: {exc}", err=True)
        sys.exit(1)


if __name__ == "__main__":  # python -m plantcheck.service.cli
    main()
