"""What a service process imports at start: every process the service, the demo and the tests
start pays for it (on a 2-core machine, seconds each)."""

from __future__ import annotations

from helpers import modules_loaded


def test_the_service_loads_neither_scipy_stats_nor_asyncua_until_it_needs_them() -> None:
    """scipy.stats (1.5 s: the store's trend reports once imported it) is not used by the
    service; asyncua (0.6-0.7 s) only by a service that reads OPC UA, when it builds its
    connector."""
    modules = "plantcheck.service.app, plantcheck.service.cli_run"
    assert modules_loaded(modules, ("scipy.stats", "asyncua")) == []


def test_a_diagnosis_worker_loads_the_chain_not_the_service_stack() -> None:
    """What the scheduler runs in its spawned workers (``warm_worker``, ``diagnose_window``,
    ``die_with_parent``) loads the chain only: the store, web and job stack cost every worker
    1.8-2 s of start and their memory."""
    from plantcheck.service import scheduler, window_diagnosis

    assert scheduler.warm_worker is window_diagnosis.warm_worker
    stacks = ("sqlalchemy", "fastapi", "apscheduler", "alembic", "asyncua", "pymodbus")
    modules = "plantcheck.service.window_diagnosis, plantcheck.service.worker_lifetime"
    assert modules_loaded(modules, stacks) == []


def test_the_served_simulator_loads_no_scipy() -> None:
    """The plant a simulator serves filters its own noise sample by sample; scipy.signal
    (1-2 s) is left to the batch simulation of records and corpora."""
    modules = "plantcheck.simulator.runner, plantcheck.simulator.export, plantcheck.service.cli_run"
    assert modules_loaded(modules, ("scipy",)) == []


def test_the_head_revision_read_from_the_files_is_alembics() -> None:
    """A service that starts on a migrated database reads the head revision without Alembic
    (its import and every migration module: about a second on a slow machine)."""
    from alembic.script import ScriptDirectory

    from plantcheck.storage.database import alembic_config, head_revision

    want = ScriptDirectory.from_config(alembic_config("sqlite://")).get_current_head()
    assert head_revision() == want
    assert modules_loaded("plantcheck.service.app", ("alembic",)) == []
