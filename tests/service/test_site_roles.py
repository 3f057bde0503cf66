"""The pieces of a site's roles that need no process (issue 28): how loops are batched into
queue jobs, and how the service shows the sources other processes read."""

from __future__ import annotations

from plantcheck.core.source_health import SourceHealth
from plantcheck.service.config import Config
from plantcheck.service.diagnosis_queue import batches_of, queue_conninfo
from plantcheck.service.runtime import REPORT_STALE_S, remote_health
from plantcheck.service.scheduler import LoopSchedule
from plantcheck.storage.source_health import ReportedHealth

S = 1_000_000


def test_loops_of_equal_period_share_batches_of_the_configured_size() -> None:
    schedules = [LoopSchedule(f"L{i}", "flow", 7200, 600 if i < 5 else 60) for i in range(7)]
    batches = batches_of(schedules, 2)
    assert [(b.loops, b.period_s) for b in batches] == [
        (("L5", "L6"), 60),
        (("L0", "L1"), 600),
        (("L2", "L3"), 600),
        (("L4",), 600),
    ]
    assert len({b.key for b in batches}) == len(batches)  # the key is the job's lock


def test_the_queue_uses_the_store_database() -> None:
    url = "postgresql+asyncpg://plantcheck:pw@db:5432/plant"
    assert queue_conninfo(url) == "postgresql://plantcheck:pw@db:5432/plant"


def _site() -> Config:
    return Config.model_validate(
        {
            "source": [
                {"name": "own", "protocol": "modbus"},
                {"name": "u1", "protocol": "modbus", "collector": "edge1"},
                {"name": "u2", "protocol": "modbus", "collector": "edge2"},
                {"name": "unused", "protocol": "modbus", "collector": "edge2"},
            ],
            "loop": [
                {"id": f"L{n}", "source": n, "pv": "hr:0:float32", "op": "hr:2:float32"}
                for n in ("own", "u1", "u2")
            ],
        }
    )


def test_sources_read_elsewhere_show_their_last_report_or_a_silent_collector() -> None:
    now = 1000 * S
    fresh = SourceHealth("u1", "modbus", "up", 10 * S, now - S, 0, "")
    old = SourceHealth("u2", "modbus", "up", 10 * S, 500 * S, 0, "")
    reports = {
        "u1": ReportedHealth(fresh, "edge1", now - 2 * S),
        "u2": ReportedHealth(old, "edge2", now - int((REPORT_STALE_S + 5) * S)),
    }
    got = {h.name: h for h in remote_health(_site(), {"own"}, reports, now)}
    assert set(got) == {"u1", "u2"}  # read here: own; no loop: unused
    assert got["u1"] == fresh
    assert got["u2"].state == "down" and got["u2"].since_us == reports["u2"].reported_us
    assert "collector 'edge2' silent" in got["u2"].last_error
    never = {h.name: h for h in remote_health(_site(), {"own"}, {}, now)}
    assert never["u1"].state == "unknown" and "has not reported" in never["u1"].last_error


def test_a_collector_reads_only_its_sources_and_their_loops() -> None:
    cfg = _site()
    assert cfg.collectors() == ["edge1", "edge2"]
    assert [s.name for s in cfg.read_by("edge2").source] == ["u2", "unused"]
    assert [lp.id for lp in cfg.read_by("edge2").loop] == ["Lu2"]
    assert [lp.id for lp in cfg.read_by("").loop] == ["Lown"]
