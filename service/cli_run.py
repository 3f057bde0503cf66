"""``plantcheck run`` (the service) and ``plantcheck demo`` (simulator + service, one command)."""

from __future__ import annotations

import contextlib
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from plantcheck.service.cli_common import fail, parse_host_port, writable_folder
from plantcheck.service.cli_store import ConfigOpt, _config, migrate_or_fail
from plantcheck.service.logs import configure_for_command

if TYPE_CHECKING:
    from plantcheck.service.config import Config

# uvicorn and the store (SQLAlchemy, alembic: about 0.4 s) are imported when a command runs,
# so that the command line itself starts at once (issue 29)


DEMO_TIMEOUT_S = 10.0
"""The demo's OPC UA request and health-probe timeout (s): its simulator is a local process
that keeps a core busy at 100x, slow to answer on a loaded machine but not gone (a loaded
machine's demo lost its session to asyncua's 1-s probe, and 130 simulated seconds with it)."""


def _check_port(host: str, port: int, what: str) -> None:
    """Refuse early, with the fix, when the API port is taken."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            raise fail(f"cannot listen on {host}:{port} ({exc.strerror}); {what}") from None


async def _check_store(cfg: Config, hint: str) -> None:
    from plantcheck.storage.buffer import DurableBuffer
    from plantcheck.storage.database import StorageError
    from plantcheck.storage.store import Store

    try:
        DurableBuffer(Path(cfg.storage.buffer_path), cfg.storage.buffer_max_samples).close()
        store = await Store.open(cfg.storage.url, config_hint=hint)
    except StorageError as exc:
        raise fail(str(exc)) from None
    await store.close()


def _server(config: object) -> Any:
    """uvicorn's server, stopping on SIGINT/SIGTERM without re-raising the signal afterwards
    (uvicorn does), so the caller's clean-up (the demo's simulator process) still runs."""
    import asyncio

    import uvicorn

    class _Server(uvicorn.Server):
        @contextlib.contextmanager
        def capture_signals(self) -> Iterator[None]:
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, self._stop_on_signal)
            try:
                yield
            finally:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    loop.remove_signal_handler(sig)

        def _stop_on_signal(self) -> None:
            if self.should_exit:
                self.force_exit = True
            self.should_exit = True

    return _Server(config)  # type: ignore[arg-type]


def _serve(cfg: Config, hint: str, progress: float | None, duration: float | None) -> None:
    import asyncio

    import uvicorn

    from plantcheck.service.app import build_app
    from plantcheck.storage.results import loop_statuses

    app = build_app(cfg, hint)
    server = _server(uvicorn.Config(app, host=cfg.api.host, port=cfg.api.port, log_level="warning"))

    async def report() -> None:
        t0 = time.monotonic()
        while not server.started:
            await asyncio.sleep(0.1)
        typer.echo(
            f"plantcheck: serving http://{cfg.api.host}:{cfg.api.port}/ (API /api/v1, "
            "docs /docs); Ctrl-C stops",
            err=True,
        )
        while not server.should_exit:
            await asyncio.sleep(progress or 3600)
            backend = getattr(app.state, "backend", None)
            if progress and backend is not None:
                rows = await loop_statuses(backend.store)
                done = [r for r in rows if r.cause is not None]
                parts = ", ".join(
                    f"{r.id} {r.cause}" + (f" S={r.S:.1f}%" if r.S is not None else "")
                    for r in done
                )
                typer.echo(
                    f"[{time.monotonic() - t0:5.0f} s] {len(done)}/{len(rows)} loops diagnosed"
                    + (f": {parts}" if parts else ""),
                    err=True,
                )
            if duration is not None and time.monotonic() - t0 >= duration:
                server.should_exit = True

    async def main() -> None:
        task = asyncio.create_task(report())
        try:
            await server.serve()
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    asyncio.run(main())


def run_cmd(
    config: ConfigOpt = None,
    host: Annotated[str | None, typer.Option(help="Listen address (default [api] host).")] = None,
    port: Annotated[
        int | None, typer.Option(min=1, max=65535, help="Listen port (default [api] port).")
    ] = None,
    migrate: Annotated[
        bool, typer.Option("--migrate", help="Create or upgrade the database schema first.")
    ] = False,
) -> None:
    """Run the service: ingest the configured sources, diagnose every loop on its rolling
    window, serve the REST API and the web page (one process; one per database)."""
    configure_for_command("info")
    cfg = _config(config)
    if not cfg.loop:
        typer.echo(
            "plantcheck: warning: no [[loop]] is configured: nothing will be collected or "
            "diagnosed (README, Configuration)",
            err=True,
        )
    api = cfg.api.model_copy(update={k: v for k, v in (("host", host), ("port", port)) if v})
    cfg = cfg.model_copy(update={"api": api})
    hint = str(config) if config else ""  # the path; the fix hints add the flag
    if migrate:
        migrate_or_fail(cfg.storage.url)
    import asyncio  # here, not at the top: `diagnose` of one record needs no event loop

    asyncio.run(_check_store(cfg, hint))
    _check_port(cfg.api.host, cfg.api.port, "set [api] port in the configuration or use --port")
    _serve(cfg, hint, None, None)


async def _work(cfg: Config, hint: str, concurrency: int) -> None:
    from plantcheck.service.diagnosis_queue import run_worker
    from plantcheck.service.metrics import ServiceMetrics
    from plantcheck.service.runtime import schedules_of
    from plantcheck.service.scheduler import DiagnosisScheduler
    from plantcheck.storage.database import StorageError
    from plantcheck.storage.store import Store

    d = cfg.scheduler
    try:
        store = await Store.open(cfg.storage.url, config_hint=hint)
    except StorageError as exc:
        raise fail(str(exc)) from None
    diagnoser = DiagnosisScheduler(
        store,
        schedules_of(cfg),
        concurrency,
        ServiceMetrics(),
        confirm=d.confirm,
        quantify_every_s=d.quantify_every_s,
        window_cache_mb=d.window_cache_mb,
        baseline_days=d.baseline_days,
        baseline_min=d.baseline_min,
    )
    try:
        await diagnoser.open_pool()
        await run_worker(
            diagnoser,
            cfg.storage.url,
            concurrency,
            heartbeat_s=d.heartbeat_s,
            stalled_after_s=d.stalled_after_s,
        )
    finally:
        await diagnoser.stop()
        await store.close()


def worker_cmd(
    config: ConfigOpt = None,
    concurrency: Annotated[
        int,
        typer.Option(
            min=1, max=64, help="Jobs run at once, each in its own diagnosis process (cores)."
        ),
    ] = 2,
) -> None:
    """Run queued diagnosis jobs ([scheduler] engine = "queue", PostgreSQL): start one on each
    machine that should diagnose, with the service's configuration file; SIGTERM stops it after
    the jobs under way (a killed worker's jobs go to another after stalled_after_s)."""
    configure_for_command("info")
    cfg = _config(config)
    if cfg.scheduler.engine != "queue":
        raise fail(
            "plantcheck worker runs jobs of the PostgreSQL job queue: set [scheduler] engine = "
            '"queue" (and a postgresql+asyncpg:// [storage] url) in the configuration'
        )
    import asyncio

    asyncio.run(_work(cfg, str(config) if config else "", concurrency))


DEMO_PORT_ATTEMPTS = 3
"""Ports the demo tries for its simulator's OPC UA server before it gives up."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def demo_config(data_dir: Path, port: int, opcua_url: str, speed: float) -> str:
    """The service configuration of the demo: the default plant over OPC UA, SQLite in
    ``data_dir``, 1-hour windows (simulated time) diagnosed every 10 s."""
    from plantcheck.simulator.export import map_toml
    from plantcheck.simulator.scenario import load_scenario

    sc = load_scenario(None)
    sc = sc.model_copy(update={"opcua": sc.opcua.model_copy(update={"url": opcua_url})})
    sampling = sc.clock.sample_time_s / speed
    tables = map_toml(sc, protocol="opcua", poll_interval_s=sampling, timeout_s=DEMO_TIMEOUT_S)
    return "\n".join(
        [
            "# written by `plantcheck demo`: the bundled simulator over OPC UA at "
            f"{speed:g}x real time",
            "[storage]",
            f'url = "sqlite+aiosqlite:///{data_dir / "demo.db"}"',
            f'buffer_path = "{data_dir / "demo-buffer.db"}"',
            "",
            "[api]",
            'host = "127.0.0.1"',
            f"port = {port}",
            "",
            "[scheduler]",
            "window_s = 3600",
            "period_s = 10",
            "quantify_every_s = 60",
            "",
            tables,
        ]
    )


def demo_cmd(
    port: Annotated[int, typer.Option(min=1, max=65535, help="Web page and API port.")] = 8000,
    speed: Annotated[
        float, typer.Option(min=10, max=400, help="Simulated seconds per wall second.")
    ] = 100.0,
    data_dir: Annotated[
        Path | None,
        typer.Option(help="Keep the demo's configuration and database here (default: temporary)."),
    ] = None,
    duration: Annotated[
        float | None, typer.Option(help="Stop after this many seconds (default: at Ctrl-C).")
    ] = None,
    admin: Annotated[
        str,
        typer.Option(
            metavar="HOST:PORT|off",
            help="Serve the simulator's admin commands here, e.g. 127.0.0.1:5021: faults, and "
            "'tune LOOP KC TI_S' to apply a retuning proposal (simulator/README.md).",
        ),
    ] = "off",
) -> None:
    """Demo: the bundled 11-loop plant simulated at high speed, ingested over OPC UA and
    diagnosed by the service on SQLite; open http://127.0.0.1:PORT/ (every loop shows its
    cause within about a minute)."""
    from plantcheck.service.config import load_config

    # the demo's terminal shows plantcheck's progress: a library's notices (asyncua's "Future
    # for request id N is already done" when a reply crosses the stop, its "Publish iteration
    # crashed" when a session is lost, which the connector logs once with its return) only at
    # --log-level debug
    configure_for_command("warning", libraries="critical")
    _check_port("127.0.0.1", port, "choose another with --port")
    if admin != "off":
        try:
            admin_host, admin_port = parse_host_port(admin)
        except ValueError as exc:
            raise fail(f"--admin: {exc} (or 'off')") from None
        _check_port(admin_host, admin_port, "choose another with --admin")
    if data_dir is not None:
        writable_folder(data_dir, f"--data-dir {data_dir}")
    with contextlib.ExitStack() as stack:
        if data_dir is None:
            data_dir = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="plantcheck-")))
        for old in data_dir.glob("demo*.db*"):
            old.unlink()
        from plantcheck.storage.database import upgrade

        cfg_path = data_dir / "plantcheck.toml"
        configs: list[Config] = []

        def prepare(opcua_url: str) -> None:
            # while the simulator starts in its process (seconds: its imports, the OPC UA
            # address space), this one writes and migrates its own side and imports the web
            # service: on two cores the demo serves 3-4 s sooner
            cfg_path.write_text(demo_config(data_dir, port, opcua_url, speed), encoding="utf-8")
            configs.append(load_config(cfg_path))
            upgrade(configs[-1].storage.url)
            import uvicorn  # noqa: F401

            import plantcheck.service.app  # noqa: F401

        opcua_url = simulator_on_a_free_port(stack, admin, speed, prepare=prepare)
        cfg = configs[-1]
        commands = "" if admin == "off" else f"; admin commands on {admin}"
        typer.echo(
            f"plantcheck demo: simulator at {speed:g}x on {opcua_url}{commands}; configuration "
            f"{cfg_path}; open http://127.0.0.1:{port}/",
            err=True,
        )
        _serve(cfg, str(cfg_path), 10.0, duration)


def simulator_on_a_free_port(
    stack: contextlib.ExitStack,
    admin: str,
    speed: float,
    choose: Callable[[], int] = _free_port,
    attempts: int = DEMO_PORT_ATTEMPTS,
    prepare: Callable[[str], None] | None = None,
) -> str:
    """Start the demo's simulator on a loopback port ``choose`` gives (stopped when ``stack``
    closes); its OPC UA URL. A port is free when chosen and may be taken before the
    simulator, a second later, binds it (by any program's outgoing connection): the
    simulator then exits, and another port is tried, ``attempts`` in all. ``prepare`` runs
    with each URL tried while its simulator starts."""
    for attempt in range(1, attempts + 1):
        opcua_port = choose()
        opcua_url = f"opc.tcp://127.0.0.1:{opcua_port}/plantcheck/"
        sim = _start_simulator(opcua_url, admin, speed)
        stack.callback(_stop_process, sim)
        if prepare is not None:
            prepare(opcua_url)
        if _wait_for_port(sim, opcua_port):
            return opcua_url
        if attempt < attempts:
            typer.echo(
                f"plantcheck demo: the simulator could not serve on port {opcua_port}; "
                "trying another",
                err=True,
            )
    raise fail(f"the simulator exited with status {sim.returncode} (see above)")


def _start_simulator(opcua_url: str, admin: str, speed: float) -> subprocess.Popen[bytes]:
    """The demo's simulator: the bundled plant over OPC UA only, in its own process."""
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "plantcheck.service.cli",
            # the demo's own terminal shows plantcheck's progress, not asyncua's notices
            "--log-level",
            "error",
            "simulate",
            "--opcua",
            opcua_url,
            "--modbus",
            "off",
            "--admin",
            admin,
            "--speed",
            f"{speed:g}",
            "--quiet",
        ],
        stdout=subprocess.DEVNULL,
    )


def _wait_for_port(proc: subprocess.Popen[bytes], port: int, timeout_s: float = 60.0) -> bool:
    """Wait until the simulator accepts connections: True; False when it exits first (it
    could not serve: its reason is on the terminal)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        with socket.socket() as s:
            s.settimeout(0.5)
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.2)
    raise fail(f"the simulator did not open its OPC UA port {port} within {timeout_s:g} s")


def _stop_process(p: subprocess.Popen[bytes]) -> None:
    p.terminate()
    try:
        p.wait(10)
    except subprocess.TimeoutExpired:
        p.kill()
