"""Store commands: ``plantcheck db upgrade``, ``plantcheck import``, ``plantcheck ingest``."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from plantcheck.core.names import check_loop_id
from plantcheck.core.vocabulary import LoopType
from plantcheck.service.cli_common import fail, parse_duration
from plantcheck.service.logs import configure_for_command
from plantcheck.storage.errors import StorageError

if TYPE_CHECKING:
    from plantcheck.service.config import Config

db_app = typer.Typer(
    help="Database schema (Alembic migrations).", no_args_is_help=True, rich_markup_mode=None
)

ConfigOpt = Annotated[
    Path | None, typer.Option("--config", help="Service configuration (default plantcheck.toml).")
]


def _config(path: Path | None) -> Config:
    from plantcheck.core.toml_config import ConfigError
    from plantcheck.service.config import Config, load_config

    if path is None and not Path("plantcheck.toml").exists():
        return Config()  # embedded default: SQLite file plantcheck.db in this folder
    try:
        return load_config(path)
    except ConfigError as exc:
        raise fail(f"invalid configuration: {exc}") from None


def _root_reason(exc: BaseException) -> str:
    """The innermost cause of a failed migration, in one line (the driver's own words)."""
    seen = exc
    while True:
        nxt = getattr(seen, "orig", None) or seen.__cause__ or seen.__context__
        if nxt is None or nxt is seen:
            break
        seen = nxt
    text = getattr(seen, "strerror", None) or str(seen) or type(seen).__name__
    return str(text).splitlines()[0]


def migrate_or_fail(url: str) -> str:
    """Create or migrate the database at ``url`` (``db upgrade``, ``run --migrate``): its
    revision, or exit 2 with one line naming the database (password hidden) and the fix."""
    from sqlalchemy.engine import make_url

    from plantcheck.storage.database import sqlite_file, upgrade

    where = make_url(url).render_as_string(hide_password=True)
    db = sqlite_file(url)
    if db is not None:
        folder = db.resolve().parent
        if not folder.is_dir():
            raise fail(
                f"cannot create the database {where}: the folder {folder} does not exist; "
                "create it or point storage.url at an existing one"
            )
    try:
        return upgrade(url)
    except Exception as exc:
        raise fail(
            f"cannot migrate the database {where}: {_root_reason(exc)}; check storage.url "
            "(host, port, user, database) and that the database server runs"
        ) from None


@db_app.command("upgrade")
def db_upgrade(config: ConfigOpt = None) -> None:
    """Create or migrate the database named in the configuration to the newest schema."""
    from sqlalchemy.engine import make_url

    cfg = _config(config)
    rev = migrate_or_fail(cfg.storage.url)
    where = make_url(cfg.storage.url).render_as_string(hide_password=True)
    typer.echo(f"database at schema revision {rev}: {where}")


def import_cmd(
    file: Annotated[Path, typer.Argument(help="Loop record (CSV, docs/contracts.md §1).")],
    loop: Annotated[str, typer.Option("--loop", help="Loop id to store the samples under.")],
    config: ConfigOpt = None,
    loop_type: Annotated[
        LoopType, typer.Option("--loop-type", help="Loop type when the loop is new.")
    ] = LoopType.other,
    sample_time: Annotated[float | None, typer.Option(help="Sample time (s).")] = None,
) -> None:
    """Backfill a recorded file into the store (idempotent: a second import adds nothing)."""
    try:
        check_loop_id(loop)
    except ValueError as exc:
        raise fail(f"--loop: {exc}") from None
    cfg = _config(config)
    import numpy as np

    from plantcheck.service.records import RecordError, read_record

    try:
        rec = read_record(file, sample_time)
    except RecordError as exc:
        raise fail(str(exc)) from None
    if rec.start_epoch_s is None:
        raise fail(f"{file}: needs a timestamp column (ISO 8601) to be stored at its real time")

    from plantcheck.core.samples import Sample
    from plantcheck.core.status_codes import BAD_DATA_ENCODING_INVALID, GOOD
    from plantcheck.storage.store import Store

    async def run() -> tuple[int, int]:
        store = await Store.open(cfg.storage.url, config_hint=str(config) if config else "")
        try:
            sigs = [s for s in ("sp", "pv", "op", "mv") if rec.get(s) is not None]
            if rec.auto is not None:
                sigs.append("mode")
            row = await store.ensure_loop(loop, loop_type.value, "import", sigs)
            before = await store.count_samples(list(row.tags.values()))
            t_us = np.round((rec.start_epoch_s + rec.t) * 1e6).astype(np.int64)  # type: ignore[operator]
            now = time.time_ns() // 1000
            n = 0
            for sig in sigs:
                vals = rec.auto.astype(float) if sig == "mode" else rec.signals[sig]  # type: ignore[union-attr]
                tid = row.tags[sig]
                rows = [
                    Sample(tid, int(t), now, float(v), GOOD)
                    if np.isfinite(v)
                    else Sample(tid, int(t), now, None, BAD_DATA_ENCODING_INVALID)
                    for t, v in zip(t_us, vals, strict=True)
                ]
                for i in range(0, len(rows), 50_000):
                    await store.write_samples(rows[i : i + 50_000])
                n += len(rows)
            return n, await store.count_samples(list(row.tags.values())) - before
        finally:
            await store.close()

    import asyncio  # here, not at the top: `diagnose` of one record needs no event loop

    try:
        n, added = asyncio.run(run())
    except StorageError as exc:
        raise fail(str(exc)) from None
    # writes are idempotent on (tag, time): say what was new, not what was read (issue 47)
    typer.echo(
        f"imported {file}: {n} samples of loop {loop} ({rec.t.size} time points), {added} new, "
        f"{n - added} already stored"
    )


def ingest_cmd(
    config: ConfigOpt = None,
    duration: Annotated[
        str | None, typer.Option(help="Stop after this long (e.g. 10m); default: until Ctrl-C.")
    ] = None,
    collector: Annotated[
        str,
        typer.Option(
            help="Read the sources whose `collector` is this name (a collector at the plant "
            "feeding the central store); default: the sources without one."
        ),
    ] = "",
) -> None:
    """Collect the configured sources into the store (no diagnosis; `plantcheck run` does both).
    On an edge machine with --collector NAME: the sources marked `collector = "NAME"`, through
    this machine's own store-and-forward buffer ([storage] buffer_path)."""
    from plantcheck.service.ingest import Ingestion

    cfg = _config(config)
    if collector and collector not in cfg.collectors():
        named = ", ".join(cfg.collectors()) or "none"
        raise fail(
            f"--collector {collector}: no [[source]] has collector = {collector!r} "
            f"(collectors named in the configuration: {named})"
        )
    if cfg.source and not cfg.read_by(collector).source:
        raise fail(
            "no source to read: every [[source]] names a collector; start this with "
            f"--collector NAME (one of {', '.join(cfg.collectors())})"
        )
    seconds = None
    if duration is not None:
        try:
            seconds = parse_duration(duration)
        except ValueError as exc:
            raise fail(f"--duration: {exc}") from None
    configure_for_command("info")

    async def run() -> None:
        ing = await Ingestion.start(
            cfg, config_hint=str(config) if config else "", collector=collector
        )
        try:
            await ing.wait(seconds)
        finally:
            await ing.stop()
        typer.echo(
            f"stored {ing.writer.stats.stored} samples; buffered {len(ing.writer.buffer)}; "
            f"dropped {ing.writer.dropped}"
        )

    import asyncio

    try:
        asyncio.run(run())
    except StorageError as exc:
        raise fail(str(exc)) from None
